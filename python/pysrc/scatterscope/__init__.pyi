"""Type stubs of the scatterscope package (see the module docstring)."""

import os
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from ._native import ScatterscopeError as ScatterscopeError

__version__: str

_Path = Union[str, "os.PathLike[str]"]

def read_tags(path: _Path) -> Dict[str, Any]:
    """Every tag of a recorded file as numpy columns."""

def bin_file(
    path: _Path,
    bin_width_ps: Optional[float] = None,
    t_start_ps: float = 0.0,
    bins: Optional[int] = None,
    channel: Optional[int] = None,
    pixels: str = "auto",
    frames: Union[str, int] = "sum",
    allow_truncated: bool = False,
    dtype: Optional[str] = None,
) -> Dict[str, Any]:
    """Bin a recorded file into transient stacks, as ``scatterscope bin``."""

def load_stack(path: _Path) -> Tuple[np.ndarray, Optional[Dict[str, Any]]]:
    """Read a stack file (EXR, or npy with its JSON sidecar)."""

def save_stack(path: _Path, data: np.ndarray, meta: Dict[str, Any]) -> None:
    """Write counts (bins, rows, cols) with their metadata dict."""

def load_image(path: _Path) -> np.ndarray:
    """Read a 2-D image (EXR, PNG, JPEG or npy) as float64."""

def measured_meta(t_start_ps: float, bin_width_ps: float, bins: int, source: str = "python") -> Dict[str, Any]:
    """Metadata for measured counts without physics."""

def psf_kernels(sampling: str = "integrated", **physics: Any) -> Dict[str, Any]:
    """The ST-PSF kernel stack of the physics."""

def simulate(image: Union[np.ndarray, str], seed: int = 0, boundary: str = "sensor", **physics: Any) -> Dict[str, Any]:
    """Simulate an array, a built-in scene or an image file through the medium."""

def reconstruct(
    data: np.ndarray,
    meta: Optional[Dict[str, Any]] = None,
    method: str = "auto",
    bin: Optional[int] = None,
    boundary: Optional[str] = None,
    background: str = "auto",
    denoiser: str = "ffdnet",
    weights: Optional[_Path] = None,
    tv_gain: float = 0.5,
    solver: str = "split",
    max_iters: Optional[int] = None,
    **physics: Any,
) -> Tuple[np.ndarray, Dict[str, Any], List[str]]:
    """Reconstruct the object from counts, as ``scatterscope reconstruct``."""

def acquire(
    device: str,
    out: _Path,
    duration_s: Optional[float] = None,
    **settings: Any,
) -> Dict[str, Any]:
    """Acquire from ``device`` as ``scatterscope acquire --device`` does."""

def acquire_mock(
    duration_s: float,
    out: _Path,
    scene: str = "usaf",
    rate_hz: float = 2e6,
    dark_rate_hz: float = 0.0,
    seed: int = 0,
    **physics: Any,
) -> Dict[str, Any]:
    """Acquire from the emulated time tagger for ``duration_s`` seconds."""

def calibrate_slab(
    reference: Any,
    captures: List[Tuple[Any, float]],
    refractive_index: float,
    predict: Optional[List[Tuple[Any, float]]] = None,
    bin_width_ps: Optional[float] = None,
    dataset: str = "out",
    irf_extent: str = "period",
    mu_a: float = 0.01,
    mu_s_reduced: float = 5.0,
    fit: Tuple[str, ...] = ("mu_a", "mu_s_reduced"),
    offset_cm: float = 0.0,
    rising_edge_share: Optional[float] = None,
    mu_s: Optional[float] = None,
    bin_ps: Optional[float] = None,
) -> Dict[str, Any]:
    """Fit a slab's mu_a and mu_s' to transmittance captures, as ``scatterscope calibrate-slab``."""
