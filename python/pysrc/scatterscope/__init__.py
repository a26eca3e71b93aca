"""scatterscope: time-resolved imaging through scattering media, from Python.

The same library as the ``scatterscope`` command, numpy in and out:

- time tags: :func:`read_tags` (every photon of a PTU, PT3, HT3 or .sstags
  file as columns) and :func:`bin_file` (tags -> ``(bins, rows, cols)``
  count stacks, as ``scatterscope bin``);
- stacks: :func:`load_stack` and :func:`save_stack` (EXR, or npy with its
  JSON sidecar), their metadata as a dict;
- physics: :func:`psf_kernels` (the ST-PSF kernels) and :func:`simulate`
  (an image through the medium, with Poisson counts); :func:`learned_case`
  (one training case of the learned reconstruction, simulated as the
  benchmark simulates, with the network's inputs);
- decay maps: :func:`decay_maps` (photons, mean arrival time, fast
  lifetime, phasors and calibrated lifetimes per pixel);
- reconstruction: :func:`reconstruct` (every method of ``scatterscope
  reconstruct`` by name), returning the image, the trace and the notes;
- calibration: :func:`calibrate_slab` (a slab's mu_a and mu_s' from
  transmittance captures);
- acquisition: :func:`acquire` (any device, as the command), and
  :func:`acquire_mock` (the emulated time tagger).

Physics keywords use the library's units: ``mu_a`` and ``mu_s`` in 1/cm,
``thickness_cm``, ``fov_cm``, times in ps (``bin_width_ps``,
``t_start_ps``, ``irf_fwhm_ps``), ``size`` in pixels, ``photons``.
Errors raise :class:`ScatterscopeError` with the library's message. Long
calls release the GIL; Ctrl-C (KeyboardInterrupt) stops a reconstruction
at its next iteration and an acquisition cleanly.
"""

from __future__ import annotations

import json
import os
import warnings
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from . import _native
from ._native import ScatterscopeError

__all__ = [
    "ScatterscopeError",
    "read_tags",
    "bin_file",
    "load_stack",
    "save_stack",
    "load_image",
    "measured_meta",
    "psf_kernels",
    "simulate",
    "learned_case",
    "decay_maps",
    "fit_lifetimes",
    "reconstruct",
    "acquire",
    "acquire_mock",
    "calibrate_slab",
    "reconstruct_embedded",
    "load_array",
    "__version__",
]

__version__: str = _native.version()


def _path(p: "os.PathLike[str] | str") -> str:
    return os.fspath(p)


def read_tags(path: "os.PathLike[str] | str") -> Dict[str, Any]:
    """Every tag of a recorded file as numpy columns.

    ``path`` is a PicoQuant file (PTU, PT3, HT3; T2 or T3) or the project's
    tag file (``.sstags``, where ``channel`` is the sensor pixel).

    Returns a dict: ``channel`` (uint16), ``macro_time`` (uint64, syncs in
    T3), ``micro_time`` (uint32, units of ``resolution_s``) per photon;
    ``marker_bits`` (uint8) and ``marker_time`` (uint64) per marker;
    ``sync_time`` (uint64, T2 syncs); ``resolution_s``, ``macro_unit_s``
    (seconds) and ``header`` (the header in words, one line each).
    """
    return _native.read_tags(_path(path))


def bin_file(
    path: "os.PathLike[str] | str",
    bin_width_ps: Optional[float] = None,
    t_start_ps: float = 0.0,
    bins: Optional[int] = None,
    channel: Optional[int] = None,
    pixels: str = "auto",
    frames: "str | int" = "sum",
    allow_truncated: bool = False,
    dtype: Optional[str] = None,
    spc_module: Optional[str] = None,
    micro_unit_ps: Optional[float] = None,
) -> Dict[str, Any]:
    """Bin a recorded file into transient stacks, as ``scatterscope bin``.

    PicoQuant files (PTU, PT3, HT3), tag files (``.sstags``) and Becker &
    Hickl files: ``.spc`` photons (``spc_module`` ``"spc-130"``, the
    default, ``"spc-600-256"`` or ``"spc-600-4096"``; ``micro_unit_ps``
    when no SPCM ``.set`` file lies beside it) and ``.sdt`` histograms
    (one stack per block of decay curves).

    ``bin_width_ps`` defaults to the file's micro-time unit, ``bins`` to
    one sync period (widened to every micro time present); ``pixels`` is
    ``auto`` (the scanned image of imaging files, else one pixel),
    ``single`` or ``channel``; ``frames`` is ``sum``, ``all`` or a frame
    number. ``dtype`` is the arrays' type: ``"uint32"`` (the counts as
    binned, handed over without a copy), ``"uint16"`` or ``"float32"``
    (an error when a count does not fit exactly); by default float32,
    or uint32 for a stack with a count above 2**24.

    Returns a dict: ``stacks`` (list of arrays ``(bins, rows, cols)``, one
    per kept frame, of the type ``dtype`` says), ``meta`` (their metadata dicts),
    ``ledger`` (where every record and photon went, the acquisition
    ledger's words: ``photons = binned + outside_window + other_channel +
    outside_region + over_budget``; earlier builds called ``photons``
    ``received``) and ``summary`` (the
    lines the command prints).
    """
    stacks, metas, ledger, summary = _native.bin_file(
        _path(path),
        bin_width_ps,
        float(t_start_ps),
        bins,
        channel,
        pixels,
        str(frames),
        allow_truncated,
        dtype,
        spc_module,
        None if micro_unit_ps is None else float(micro_unit_ps),
    )
    return {
        "stacks": list(stacks),
        "meta": list(metas),
        "ledger": ledger,
        "summary": list(summary),
    }


def load_stack(path: "os.PathLike[str] | str") -> Tuple[np.ndarray, Optional[Dict[str, Any]]]:
    """Read a stack file (EXR, or npy with its JSON sidecar).

    Returns ``(data, meta)``: counts ``(bins, rows, cols)`` and the
    metadata dict (``None`` for a plain array without one). The counts are
    float32, or uint32 when some exceed 2**24 (float32 holds whole numbers
    exactly only up to there), so a stack round-trips bit for bit.
    """
    data, meta = _native.load_stack(_path(path))
    return data, (json.loads(meta) if meta is not None else None)


def save_stack(path: "os.PathLike[str] | str", data: np.ndarray, meta: Dict[str, Any]) -> None:
    """Write counts ``(bins, rows, cols)`` with their metadata dict.

    The extension picks the format: ``.exr`` (metadata in the header) or
    ``.npy`` (metadata in ``.json`` beside it). The library's checks apply:
    finite, non-negative counts whose shape matches the metadata.
    """
    array = np.ascontiguousarray(data, dtype=np.float32)
    if array.ndim != 3:
        raise ScatterscopeError(f"a stack is (bins, rows, cols); this array has shape {array.shape}")
    counts = None
    if np.issubdtype(np.asarray(data).dtype, np.integer):
        # Whole counts: passed exactly, stored exactly where float32 rounds.
        raw = np.asarray(data)
        if raw.size and (raw.min() < 0 or raw.max() > np.iinfo(np.uint32).max):
            raise ScatterscopeError("counts must lie in 0 .. 2**32 - 1")
        counts = np.ascontiguousarray(raw, dtype=np.uint32)
    _native.save_stack(_path(path), array, json.dumps(meta), counts)


def load_image(path: "os.PathLike[str] | str") -> np.ndarray:
    """Read a 2-D image (EXR, PNG, JPEG or npy) as float64, e.g. the
    ``reconstruction.exr`` of ``scatterscope reconstruct``."""
    return _native.load_image(_path(path))


def measured_meta(t_start_ps: float, bin_width_ps: float, bins: int, source: str = "python") -> Dict[str, Any]:
    """Metadata for measured counts: ``bins`` bins of ``bin_width_ps`` from
    ``t_start_ps`` (no physics recorded)."""
    return json.loads(_native.measured_meta(float(t_start_ps), float(bin_width_ps), int(bins), source))


def psf_kernels(sampling: str = "integrated", **physics: Any) -> Dict[str, Any]:
    """The ST-PSF kernel stack of the physics (default: the paper preset).

    ``sampling`` is ``integrated`` (over pixel area and bin duration) or
    ``point``. Returns ``kernels`` (float64 ``(kept bins, rows, cols)``),
    ``bins`` (one dict per time bin: start, end, expected photons, kept,
    lateral sigma) and ``setup`` (the resolved physics).
    """
    kernels, bins, setup = _native.psf_kernels(sampling, **physics)
    return {"kernels": kernels, "bins": json.loads(bins), "setup": json.loads(setup)}


def simulate(
    image: "np.ndarray | str", seed: int = 0, boundary: str = "sensor", **physics: Any
) -> Dict[str, Any]:
    """Simulate an object through the medium onto the sensor.

    ``image`` is a square array (rows x cols, finite, >= 0; the sensor
    takes its size unless ``size`` is given), or the name of a built-in
    scene (``usaf``, ``star``, ``text``, ``disks``) or an image file, as
    ``scatterscope simulate --scene`` takes it. ``boundary`` is ``sensor``
    (edges) or ``periodic``. Returns ``counts`` (Poisson, deterministic
    for ``seed``) and ``expected`` (noise-free), float32 ``(bins, rows,
    cols)``, ``meta`` (the counts' metadata, for :func:`reconstruct` and
    :func:`save_stack`) and ``truth`` (the object on the sensor grid).
    """
    if isinstance(image, (str, os.PathLike)):
        counts, expected, meta, truth = _native.simulate_scene(_path(image), int(seed), boundary, **physics)
        return {"counts": counts, "expected": expected, "meta": json.loads(meta), "truth": truth}
    array = np.ascontiguousarray(image, dtype=np.float64)
    if array.ndim != 2:
        raise ScatterscopeError(f"an image is (rows, cols); this array has shape {array.shape}")
    counts, expected, meta = _native.simulate(array, int(seed), boundary, **physics)
    return {"counts": counts, "expected": expected, "meta": json.loads(meta), "truth": array}


def learned_case(
    image: np.ndarray,
    sensor_px: int,
    seed: int = 0,
    background_share: float = 0.0,
    discretisation: str = "integrated",
    offset: Tuple[int, int] = (0, 0),
    true_physics: Optional[Dict[str, Any]] = None,
    **physics: Any,
) -> Dict[str, Any]:
    """One training case of ``--method learned``: ``image`` (a square
    object grid larger than the sensor of ``sensor_px`` pixels, which sees
    its centre at the physics' pixel pitch) simulated as the benchmark
    simulates it, plus ``background_share`` times the mean expected count
    per pixel and bin. Returns ``inputs`` (the network's float32
    ``(channels, rows, cols)``, computed by the function the reconstruction
    runs), ``truth`` (the object on the sensor) and ``scale``,
    ``photons_per_pixel``, ``kernel_width_px``, ``background_share``, and
    the operator of the reconstruction's data steps: ``counts`` (summed
    over bins), ``kernel`` (the time-summed kernel on the model's grid,
    origin-centred), ``sensor_offset`` (the sensor's first row and column
    on that grid), ``background`` (summed over bins, per pixel) and
    ``base_grid`` (the last Richardson-Lucy iterate on the grid).

    ``discretisation`` is how the simulation discretises the ST-PSF:
    ``integrated`` (the reconstruction's own model), ``point`` (pixel and
    bin centres) or ``half-pitch`` (a grid of half the pitch, its 2 x 2
    blocks summed from ``offset`` fine pixels); ``true_physics`` (physics
    keywords) is the medium the light really crossed when the stated
    ``physics`` are only roughly right.
    """
    array = np.ascontiguousarray(image, dtype=np.float64)
    if array.ndim != 2:
        raise ScatterscopeError(f"an image is (rows, cols); this array has shape {array.shape}")
    inputs, truth, facts = _native.learned_case(
        array,
        int(sensor_px),
        int(seed),
        float(background_share),
        discretisation,
        (int(offset[0]), int(offset[1])),
        true_physics,
        **physics,
    )
    return {"inputs": inputs, "truth": truth, **facts}


def decay_maps(
    counts: np.ndarray,
    meta: Dict[str, Any],
    frequency_hz: Optional[float] = None,
    harmonics: Tuple[int, ...] = (1, 2),
    min_photons: float = 20.0,
    onset_ps: Optional[float] = None,
    reference_phasors: Optional[List[Tuple[float, float]]] = None,
    reference_lifetime_ps: float = 0.0,
    all_bins: bool = False,
) -> Dict[str, Any]:
    """Per-pixel decay maps of a stack of counts ``(bins, rows, cols)``
    (uint16, uint32 or float32, as :func:`bin_file` returns) with its
    metadata ``meta``, as ``scatterscope lifetime`` computes them:
    ``photons``, ``mean_time_ps`` and ``variance_ps2`` (after the onset),
    ``fast_lifetime_ps`` (SymPhoTime's conventions: photons at their
    bins' starts, time zero on the decay's rising flank),
    ``fast_lifetime_centred_ps`` (bins' centres, the interpolated onset),
    ``g1``, ``s1``, ... per harmonic and, with
    ``reference_phasors`` (one ``(g, s)`` per harmonic, of a reference of
    ``reference_lifetime_ps``), ``g1_calibrated``, ``s1_calibrated``,
    ``phase_lifetime1_ps``, ``modulation_lifetime1_ps``; ``mask`` (True
    where fewer than ``min_photons``: NaN in the maps), ``onset_ps``,
    ``frequency_hz`` and ``notes``. The frequency defaults to the
    recording's (``meta["laser_frequency_hz"]``). Only the bins the
    instrument recorded whole are mapped (``meta["recorded_bins"]``, as
    the command), unless ``all_bins``.
    """
    f = frequency_hz if frequency_hz is not None else meta.get("laser_frequency_hz")
    if f is None:
        raise ScatterscopeError(
            "decay_maps: the stack's metadata states no laser frequency: give frequency_hz"
        )
    starts = [float(t) for t in meta["bin_starts_ps"]]
    recorded = _recorded_window(meta, all_bins)
    if recorded is not None:
        first, end = recorded
        counts, starts = counts[first:end], starts[first:end]
    array = counts if counts.dtype in (np.uint16, np.uint32, np.float32) else counts.astype(np.float32)
    return _native.decay_maps(
        np.ascontiguousarray(array),
        starts,
        float(meta["bin_width_ps"]),
        float(f),
        [int(h) for h in harmonics],
        float(min_photons),
        onset_ps,
        reference_phasors,
        float(reference_lifetime_ps),
    )


def _recorded_window(meta: Dict[str, Any], all_bins: bool) -> Optional[Tuple[int, int]]:
    """The bins ``(first, end)`` the instrument recorded whole, as the
    stack's metadata states them; None when it states none or
    ``all_bins`` asks for every bin."""
    recorded = meta.get("recorded_bins")
    if all_bins or not recorded:
        return None
    return int(recorded["first"]), int(recorded["end"])


def _whole_counts(function: str, counts: Any) -> np.ndarray:
    """`counts` as uint16 or uint32, as the library takes them: a float32
    stack (bin_file's other dtype) of whole counts is converted, anything
    else refused by name."""
    if not isinstance(counts, np.ndarray):
        raise ScatterscopeError(
            f"{function}: counts must be a numpy array (bins, rows, columns), as bin_file returns, "
            f"not {type(counts).__name__}"
        )
    if counts.dtype in (np.uint16, np.uint32):
        return counts
    if counts.dtype.kind == "f":
        bad = ~(np.isfinite(counts) & (counts >= 0) & (counts <= 2**32 - 1) & (counts == np.round(counts)))
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ScatterscopeError(
                f"{function}: counts at {where} hold {counts[where]}: give whole photon counts >= 0"
            )
        return counts.astype(np.uint32)
    raise ScatterscopeError(
        f"{function}: counts must be uint16, uint32 or whole float counts (bin_file's dtypes), not {counts.dtype}"
    )


def _whole_number(function: str, name: str, value: Any) -> int:
    """`value` as a whole number >= 0, else an error naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ScatterscopeError(f"{function}: {name} {value!r}: give a whole number >= 0")
    return int(value)


def fit_lifetimes(
    counts: np.ndarray,
    meta: Dict[str, Any],
    components: int = 1,
    irf: "str | np.ndarray" = "edge",
    least_squares: bool = False,
    binning: int = 0,
    min_photons: float = 100.0,
    global_fit: bool = False,
    window: Optional[Tuple[int, int]] = None,
    incomplete_decay: bool = True,
    fit_irf_shift: bool = False,
    frequency_hz: Optional[float] = None,
    all_bins: bool = False,
) -> Dict[str, Any]:
    """Lifetimes of a stack of counts ``(bins, rows, cols)`` (uint16 or
    uint32, as :func:`bin_file` returns) with its metadata ``meta``, fitted
    as ``scatterscope fit`` fits them: 1 to 3 exponentials and a
    background reconvolved with the IRF (``irf``: an array of photons per
    bin, ``"gaussian"``, ``"edge"`` or ``"none"`` for a tail fit), by
    Poisson maximum likelihood (or weighted least squares), per pixel after
    ``binning``, or with the lifetimes shared (``global_fit``). Returns
    float64 maps ``tau1_ps``, ``tau1_error_ps``, ``a1``, ``a1_fraction``,
    ``intensity_fraction1``, ... ``tau_amplitude_ps``,
    ``tau_intensity_ps``, ``background``, ``reduced_chi2``, ``deviance``
    (NaN where ``mask``), ``photons``, the summed decay's fit and ``notes``.
    The frequency (for the earlier pulses' light) defaults to the
    recording's; the default window keeps to the bins the instrument
    recorded whole (``meta["recorded_bins"]``, as ``bin_file`` gives it),
    unless ``all_bins``. A measured IRF's shift is held at 0 (recorded
    with the sample) unless ``fit_irf_shift``.
    """
    counts = _whole_counts("fit_lifetimes", counts)
    if not isinstance(meta, dict) or "bin_starts_ps" not in meta or "bin_width_ps" not in meta:
        raise ScatterscopeError(
            f"fit_lifetimes: meta must be the stack's metadata (a dict with bin_starts_ps and "
            f"bin_width_ps, as bin_file gives it), not {type(meta).__name__}"
        )
    components = _whole_number("fit_lifetimes", "components", components)
    binning = _whole_number("fit_lifetimes", "binning", binning)
    if window is not None:
        if (isinstance(window, (str, bytes)) or len(window) != 2
                or not all(isinstance(v, (int, np.integer)) for v in window)):
            raise ScatterscopeError(
                f"fit_lifetimes: window {window!r}: give (first, end), two whole bin numbers"
            )
    f = frequency_hz if frequency_hz is not None else meta.get("laser_frequency_hz")
    if isinstance(irf, str):
        kind, decay = irf, None
    else:
        kind, decay = "measured", [float(v) for v in np.asarray(irf, np.float64).ravel()]
    return _native.fit_lifetimes(
        counts,
        [float(t) for t in meta["bin_starts_ps"]],
        float(meta["bin_width_ps"]),
        None if f is None else float(f),
        int(components),
        kind,
        decay,
        bool(least_squares),
        int(binning),
        float(min_photons),
        bool(global_fit),
        None if window is None else (int(window[0]), int(window[1])),
        bool(incomplete_decay),
        bool(fit_irf_shift),
        _recorded_window(meta, all_bins),
    )


def _trace(trace: Dict[str, Any]) -> Dict[str, Any]:
    rows = trace.pop("rows", [])
    keys: List[str] = sorted({k for r in rows for k in r})
    trace["rows"] = {
        k: np.array([np.nan if r.get(k) is None else r.get(k) for r in rows], dtype=np.float64) for k in keys
    }
    return trace


def reconstruct(
    data: np.ndarray,
    meta: Optional[Dict[str, Any]] = None,
    method: str = "auto",
    bin: Optional[int] = None,
    boundary: Optional[str] = None,
    background: str = "auto",
    denoiser: str = "ffdnet",
    weights: "os.PathLike[str] | str | None" = None,
    tv_gain: float = 0.5,
    solver: str = "split",
    max_iters: Optional[int] = None,
    learned_weights: "os.PathLike[str] | str | None" = None,
    **physics: Any,
) -> Tuple[np.ndarray, Dict[str, Any], List[str]]:
    """Reconstruct the object from counts, as ``scatterscope reconstruct``.

    ``data`` is ``(bins, rows, cols)`` photon counts and ``meta`` their
    metadata (from :func:`simulate`, :func:`bin_file` or
    :func:`load_stack`); without it the physics keywords describe the
    counts. ``method`` is one of ``auto`` (the default: the learned
    reconstruction inside its trained ranges, kept only where it explains
    held-back counts as well as ``rl-sum`` with its cross-validated stop,
    else that ``rl-sum``; ``rl-stack`` outside the ranges; the notes say
    which and why), ``learned``, ``pnp``, ``pnp-sum``, ``pnp-slice``,
    ``rl``, ``rl-sum``, ``rl-stack``, ``scaled-counts`` (the single-bin
    methods need ``bin``). ``denoiser`` (``ffdnet``, ``tv``, ``identity``),
    ``weights``, ``tv_gain`` and ``solver`` (``split``, ``admm-lbfgs``) are
    the CLI's flags of the same names; ``background`` is ``auto``, ``none``
    or counts per pixel and bin; ``learned_weights`` is a learned network's
    weights file (``training/train_unrolled.py``'s, e.g. trained with
    ``--medium monte-carlo``) for ``learned`` and ``auto`` instead of the
    embedded one, as ``--learned-weights``.

    Returns ``(image, trace, notes)``: the float64 image, the trace
    (``method``, ``prior``, ``wall_s`` and ``rows``: per-iteration arrays
    such as ``wall_s``, ``deviance``, ``objective``; NaN where a method has
    none) and the notes (what was assumed and left out, the stop).
    Ctrl-C stops it at the next iteration.
    """
    array = np.ascontiguousarray(data, dtype=np.float32)
    if array.ndim != 3:
        raise ScatterscopeError(f"counts are (bins, rows, cols); this array has shape {array.shape}")
    image, trace, notes = _native.reconstruct(
        array,
        None if meta is None else json.dumps(meta),
        method,
        bin,
        boundary,
        str(background),
        denoiser,
        None if weights is None else _path(weights),
        float(tv_gain),
        solver,
        max_iters,
        None if learned_weights is None else _path(learned_weights),
        **physics,
    )
    return image, _trace(json.loads(trace)), list(notes)


def acquire(
    device: str,
    out: "os.PathLike[str] | str",
    duration_s: Optional[float] = None,
    **settings: Any,
) -> Dict[str, Any]:
    """Acquire from ``device`` as ``scatterscope acquire --device DEVICE``.

    One request in the library serves both: the same defaults (2 s; a
    replay: the whole recording; ``duration_s=0``: until the device stops),
    the same refusals and messages (a PicoQuant-only setting for another
    device, an offset the vendor's library cannot take) and the same files
    in ``out``. ``settings`` are the command's flags in the library's
    units: the mock's ``scene``, ``rate_hz``, ``dark_rate_hz``,
    ``afterpulse``, ``seed``, ``mock_delay_ps``, ``max_photons``,
    ``unpaced``, ``replay_batches``, ``faults``; ``t0_ps`` or ``t0_from``,
    ``roi`` (``"X,Y,W,H"``), ``micro_time_unit_ps``, ``tags``, ``speed``,
    ``ome_tiff``; a PicoQuant device's ``vendor_lib``, ``sync_divider``,
    ``sync_level_mv``, ``sync_edge`` and ``marker_edge`` and ``input_edge``
    (``"rising"``/``"falling"``), ``sync_zero_cross_mv``,
    ``sync_offset_ps``, ``input_level_mv``, ``input_zero_cross_mv``,
    ``input_offsets_ps`` (a list), ``binning``, ``t3_offset_ps``, ``scan``
    (``"64x64"``), ``channel``, ``pixels``, ``ptu``, ``no_ptu``; any other
    keyword is a physics keyword (``size``, ``bin_width_ps``, ...). The
    old keys ``resolution_ps`` and ``offset_ps`` still work, with a
    ``FutureWarning``.
    Returns ``stack``, ``meta``, ``record`` and ``summary`` as
    :func:`acquire_mock`. Ctrl-C ends it cleanly, then raises
    KeyboardInterrupt.
    """
    for old, new in (("resolution_ps", "micro_time_unit_ps"), ("offset_ps", "t3_offset_ps")):
        if old in settings:
            warnings.warn(f"acquire: {old} is now {new}; the old name still works", FutureWarning, stacklevel=2)
            settings[new] = settings.pop(old)
    stack, meta, record, summary = _native.acquire(
        device, _path(out), None if duration_s is None else float(duration_s), **settings
    )
    return {"stack": stack, "meta": json.loads(meta), "record": json.loads(record), "summary": list(summary)}


def acquire_mock(
    duration_s: float,
    out: "os.PathLike[str] | str",
    scene: str = "usaf",
    rate_hz: float = 2e6,
    dark_rate_hz: float = 0.0,
    seed: int = 0,
    **physics: Any,
) -> Dict[str, Any]:
    """Acquire from the emulated time tagger for ``duration_s`` seconds.

    The mock samples photons from the ST-PSF of ``scene`` (``usaf``,
    ``star``, ``text``, ``disks`` or an image file) through the physics;
    ``out`` receives the command's files (stack, record, contact sheet).
    Returns ``stack`` (float32 ``(bins, rows, cols)``), ``meta``, ``record``
    (the acquisition's record: device, the ledger of every photon, why it ended) and
    ``summary`` (the lines ``scatterscope acquire`` prints). Ctrl-C ends it
    cleanly, then raises KeyboardInterrupt. :func:`acquire` with
    ``device="mock"``.
    """
    if not (duration_s > 0):
        raise ScatterscopeError(f"duration_s = {duration_s}: give a positive number of seconds")
    return acquire(
        "mock", out, duration_s, scene=scene, rate_hz=float(rate_hz), dark_rate_hz=float(dark_rate_hz),
        seed=int(seed), **physics
    )


def load_array(path: "os.PathLike[str] | str", name: Optional[str] = None) -> np.ndarray:
    """The numeric array ``name`` (or the file's only one) of a MATLAB file
    (level 5 or v7.3) or an ``.npy`` file, as float64 in the file's own
    dimensions (MATLAB's rows first)."""
    return _native.load_array(_path(path), name)


def reconstruct_embedded(
    cube: np.ndarray,
    pitch_cm: Tuple[float, float],
    bin_width_ps: float,
    front_thickness_cm: float,
    back_thickness_cm: float,
    mu_s_reduced: float,
    mu_a: float,
    refractive_index: float,
    beam: str = "plane",
    beam_centre: str = "0cm,0cm",
    time_zero_ps: Optional[float] = None,
    fit_scattering: bool = False,
    fit_absorption: bool = False,
    time_groups: int = 8,
    max_iters: int = 5000,
    iterations: Optional[int] = None,
    mask: Optional[np.ndarray] = None,
    subtracted_background: Optional[float] = None,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, Dict[str, Any]]:
    """Reconstruct an object inside a scattering medium from a SPAD camera's
    cube, as ``scatterscope embedded``: the beam crosses the front slab,
    lights the object (a thin mask), and its light crosses the back slab to
    the imaged face.

    ``cube`` is (bins, rows, columns), any real type and sign (a subtracted
    background leaves negatives); ``pitch_cm`` the pixels' (x, y) pitch on
    the face; lengths in cm, coefficients in 1/cm (both slabs alike),
    ``beam`` ``"plane"`` or a Gaussian's FWHM with its unit (``"6cm"``).
    ``time_zero_ps`` (the pulse's entry into the front slab after bin 0's
    start) is fitted to the cube's time profile when ``None`` (with both slabs'
    scattering or absorption factor too where ``fit_scattering`` or
    ``fit_absorption``); ``mask`` (rows,
    columns) is True at bad pixels (filtered, hot and dead ones are found
    without it); ``subtracted_background`` (counts per pixel and bin) is
    needed only where the cube has too few bins before the light.

    Returns the relative transmission (rows, columns), the beam's light at
    the object plane, the pixels used (bool) and the report (a dict: the
    noise model chosen and its figures, the pixels left out, the time zero,
    the fit, and ``notes``, every line the command prints).
    """
    trans, beam_map, used, report = _native.reconstruct_embedded(
        np.ascontiguousarray(cube, dtype=np.float64), tuple(pitch_cm), float(bin_width_ps),
        float(front_thickness_cm), float(back_thickness_cm), float(mu_s_reduced), float(mu_a),
        float(refractive_index), beam, beam_centre,
        None if time_zero_ps is None else float(time_zero_ps), bool(fit_scattering), bool(fit_absorption),
        int(time_groups),
        int(max_iters), None if iterations is None else int(iterations),
        None if mask is None else np.ascontiguousarray(mask, dtype=bool),
        None if subtracted_background is None else float(subtracted_background),
    )
    return trans, beam_map, used, json.loads(report)


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
    """Fit a slab's absorption and reduced scattering to transmittance
    captures, as ``scatterscope calibrate-slab``.

    ``reference`` is the instrument response measured without the slab and
    each capture a ``(histogram, thickness_cm)`` pair; a histogram is a file
    (MATLAB dataset ``dataset``, a stack, a tag file) or a 1-D array of
    counts (then ``bin_width_ps`` is needed). ``predict`` captures are left out of
    the fit and predicted with the fitted medium. ``fit`` names the free
    parameters (``mu_a``, ``mu_s_reduced``, ``offset``); ``mu_a`` and
    ``mu_s_reduced`` (mu_s', 1/cm) are their starts or fixed values.
    ``mu_s``, the old name of ``mu_s_reduced`` (as an argument and in
    ``fit``), and ``bin_ps``, the old name of ``bin_width_ps``, still work
    with a ``FutureWarning``.

    Returns ``mu_a_per_cm``, ``mu_s_reduced_per_cm`` and ``offset_cm`` (each
    ``value``, ``standard_error``, ``fitted``), ``chi2_per_dof``,
    ``seconds``, ``lines`` (what the command prints) and ``material_toml``
    (the material file ``scatterscope hidden --material`` reads; called
    ``medium_toml`` in earlier builds).
    """

    def arg(h: Any) -> Any:
        if isinstance(h, (str, os.PathLike)):
            return _path(h)
        return np.ascontiguousarray(h, dtype=np.float64)

    if mu_s is not None:
        warnings.warn(
            "calibrate_slab: mu_s is now mu_s_reduced (the reduced scattering coefficient mu_s'); "
            "the old name still works",
            FutureWarning,
            stacklevel=2,
        )
        mu_s_reduced = mu_s
    if bin_ps is not None:
        warnings.warn(
            "calibrate_slab: bin_ps is now bin_width_ps; the old name still works",
            FutureWarning,
            stacklevel=2,
        )
        bin_width_ps = bin_ps
    for old, new in _native.renamed_parameters(list(fit)):
        warnings.warn(
            f"calibrate_slab: fit name {old} is now {new}; the old name still works",
            FutureWarning,
            stacklevel=2,
        )
    kwargs: Dict[str, Any] = {}
    if rising_edge_share is not None:
        kwargs["rising_edge_share"] = float(rising_edge_share)
    out = _native.calibrate_slab(
        arg(reference),
        [(arg(h), float(t)) for h, t in captures],
        float(refractive_index),
        [(arg(h), float(t)) for h, t in (predict or [])],
        bin_width_ps,
        dataset,
        irf_extent,
        float(mu_a),
        float(mu_s_reduced),
        list(fit),
        float(offset_cm),
        **kwargs,
    )
    return json.loads(out)
