"""Type stubs of the compiled module; the documented API is `scatterscope`."""

from typing import Any, Dict, List, Optional, Tuple

import numpy as np

class ScatterscopeError(Exception):
    """An error of the scatterscope library; its message names the file, field and value."""

def version() -> str: ...
def read_tags(path: str) -> Dict[str, Any]: ...
def bin_file(
    path: str,
    bin_width_ps: Optional[float] = ...,
    t_start_ps: float = ...,
    bins: Optional[int] = ...,
    channel: Optional[int] = ...,
    pixels: str = ...,
    frames: str = ...,
    allow_truncated: bool = ...,
    dtype: Optional[str] = ...,
) -> Tuple[List[np.ndarray], List[Dict[str, Any]], Dict[str, Any], List[str]]: ...
def renamed_parameters(names: List[str]) -> List[Tuple[str, str]]: ...
def load_stack(path: str) -> Tuple[np.ndarray, Optional[str]]: ...
def load_image(path: str) -> np.ndarray: ...
def save_stack(path: str, data: np.ndarray, meta_json: str, counts: Optional[np.ndarray] = ...) -> None: ...
def measured_meta(t_start_ps: float, bin_width_ps: float, bins: int, source: str) -> str: ...
def psf_kernels(sampling: str = ..., **physics: Any) -> Tuple[np.ndarray, str, str]: ...
def simulate(image: np.ndarray, seed: int = ..., boundary: str = ..., **physics: Any) -> Tuple[np.ndarray, np.ndarray, str]: ...
def simulate_scene(scene: str, seed: int = ..., boundary: str = ..., **physics: Any) -> Tuple[np.ndarray, np.ndarray, str, np.ndarray]: ...
def learned_case(
    image: np.ndarray, sensor_px: int, seed: int = ..., background_share: float = ..., **physics: Any
) -> Tuple[np.ndarray, np.ndarray, Dict[str, float]]: ...
def decay_maps(
    counts: np.ndarray,
    bin_starts_ps: List[float],
    bin_width_ps: float,
    frequency_hz: float,
    harmonics: List[int] = ...,
    min_photons: float = ...,
    onset_ps: Optional[float] = ...,
    reference_phasors: Optional[List[Tuple[float, float]]] = ...,
    reference_lifetime_ps: float = ...,
) -> Dict[str, Any]: ...
def reconstruct(
    data: np.ndarray,
    meta_json: Optional[str] = ...,
    method: str = ...,
    bin: Optional[int] = ...,
    boundary: Optional[str] = ...,
    background: str = ...,
    denoiser: str = ...,
    weights: Optional[str] = ...,
    tv_gain: float = ...,
    solver: str = ...,
    max_iters: Optional[int] = ...,
    **physics: Any,
) -> Tuple[np.ndarray, str, List[str]]: ...
def acquire(
    device: str,
    out: str,
    duration_s: Optional[float] = ...,
    **settings: Any,
) -> Tuple[np.ndarray, str, str, List[str]]: ...
def calibrate_slab(
    reference: Any,
    captures: List[Tuple[Any, float]],
    refractive_index: float,
    predict: List[Tuple[Any, float]] = ...,
    bin_ps: Optional[float] = ...,
    dataset: str = ...,
    irf_extent: str = ...,
    mu_a: float = ...,
    mu_s_reduced: float = ...,
    fit: List[str] = ...,
    offset_cm: float = ...,
    rising_edge_share: float = ...,
) -> str: ...
