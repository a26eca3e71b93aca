//! `scatterscope._native`: the library's functions over numpy arrays. The
//! Python package (`pysrc/scatterscope`) wraps these in documented
//! functions; this module only converts (arrays, dicts as JSON, names) and
//! calls the library, releasing the GIL for the work and turning errors
//! into `ScatterscopeError` with the library's message.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ndarray::{Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyException, PyKeyError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use scatterscope::Named;
use scatterscope::calibrate::histogram::TimeHistogram;
use scatterscope::calibrate::transmittance::{Capture, RISING_EDGE_CONVENTION, SlabFitOptions};
use scatterscope::config::{PhysicsOverrides, parse_medium, parse_preset};
use scatterscope::denoise::prior::{PriorKind, PriorSpec};
use scatterscope::formats::becker_hickl::spc::{SpcModule, SpcOptions};
use scatterscope::forward::Boundary;
use scatterscope::physics::{KernelStack, Sampling};
use scatterscope::reconstruct::input::{InputSpec, prepare};
use scatterscope::reconstruct::method::{Method, MethodOptions, Solver, run_method};
use scatterscope::reconstruct::problem::BackgroundChoice;
use scatterscope::report::calibration::{IrfExtent, calibrate_slab as lib_calibrate_slab};
use scatterscope::stack::{Stack, StackMeta};
use scatterscope::tags::bin_file::{BinSpec, Pixels, bin_file_counts as lib_bin_file_counts};
use scatterscope::tags::binning::FrameSelect;

/// The extension's allocator (see the dependency's comment in Cargo.toml:
/// glibc malloc inside a Python process doubled the time of rl-stack).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

// Declared under the package's own name (the package re-exports it), so
// that pickle finds it as `scatterscope.ScatterscopeError` and the error
// crosses a process boundary (multiprocessing, concurrent.futures).
pyo3::create_exception!(
    scatterscope,
    ScatterscopeError,
    PyException,
    "An error of the scatterscope library; its message names the file, field and value."
);

/// The error and its sources, as one exception.
fn err<E: std::error::Error>(e: E) -> PyErr {
    ScatterscopeError::new_err(scatterscope::error_text(&e))
}

fn msg(text: impl Into<String>) -> PyErr {
    ScatterscopeError::new_err(text.into())
}

/// A computation abandoned because Python asked (KeyboardInterrupt).
struct Cancelled;

/// Runs `work` on its own thread with the GIL released, checking Python's
/// signals every 50 ms. On KeyboardInterrupt `cancel` is set; work that
/// watches it ends early, and the interrupt is raised once it has.
fn interruptible<T: Send + 'static>(
    py: Python<'_>,
    cancel: Arc<AtomicBool>,
    work: impl FnOnce() -> T + Send + 'static,
) -> PyResult<T> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
        let _ = tx.send(out);
    });
    let mut interrupt: Option<PyErr> = None;
    let mut rx = rx;
    loop {
        // The receiver goes into the GIL-free wait and comes back.
        let (got, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
        rx = back;
        match got {
            Ok(Ok(v)) => {
                return match interrupt {
                    Some(e) => Err(e),
                    None => Ok(v),
                };
            }
            Ok(Err(payload)) => {
                if payload.is::<Cancelled>() {
                    return Err(interrupt.unwrap_or_else(|| msg("cancelled")));
                }
                let text = payload
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "unknown".into());
                return Err(msg(format!("internal error (please report): {text}")));
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if interrupt.is_none()
                    && let Err(e) = py.check_signals()
                {
                    cancel.store(true, Ordering::Relaxed);
                    interrupt = Some(e);
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(msg("the worker thread ended without a result"));
            }
        }
    }
}

/// The physics overrides named in `kw` (the CLI's physics flags, in the
/// library's units: 1/cm, cm, ps, pixels, photons); unknown keys are an
/// error naming them.
fn overrides(kw: Option<&Bound<'_, PyDict>>) -> PyResult<PhysicsOverrides> {
    let mut o = PhysicsOverrides::default();
    let Some(kw) = kw else { return Ok(o) };
    for (key, value) in kw.iter() {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        let f = || value.extract::<f64>();
        let u = || value.extract::<usize>();
        match key.as_str() {
            "preset" => o.preset = Some(parse_preset(&value.extract::<String>()?).map_err(msg)?),
            "config" => o.config = Some(PathBuf::from(value.extract::<String>()?)),
            "mu_a" => o.mu_a = Some(f()?),
            "mu_s" => o.mu_s = Some(f()?),
            "g" => o.g = Some(f()?),
            "n" => o.n = Some(f()?),
            "thickness_cm" => o.thickness = Some(f()?),
            "medium" => o.medium = Some(parse_medium(&value.extract::<String>()?).map_err(msg)?),
            "fov_cm" => o.fov = Some(f()?),
            "size" => o.size = Some(u()?),
            "bin_width_ps" => o.bin_width = Some(f()?),
            "t_start_ps" => o.t_start = Some(f()?),
            "bins" => o.bins = Some(u()?),
            "photons" => o.photons = Some(f()?),
            "min_bin_photons" => o.min_bin_photons = Some(f()?),
            "irf_fwhm_ps" => o.irf_fwhm = Some(f()?),
            "irf_tail_ps" => o.irf_tail = Some(f()?),
            "irf_from" => o.irf_from = Some(PathBuf::from(value.extract::<String>()?)),
            "irf_parametric" => o.irf_parametric = value.extract()?,
            "irf_bin_width_ps" | "irf_bin_ps" => o.irf_bin_width = Some(f()?),
            other => {
                return Err(PyKeyError::new_err(format!(
                    "unknown physics keyword `{other}` (known: preset, config, mu_a, mu_s, g, n, thickness_cm, medium, fov_cm, size, bin_width_ps, t_start_ps, bins, photons, min_bin_photons, irf_fwhm_ps, irf_tail_ps, irf_from, irf_parametric, irf_bin_width_ps)"
                )));
            }
        }
    }
    Ok(o)
}

fn named<T: Named>(what: &str, name: &str) -> PyResult<T> {
    T::from_name(name).ok_or_else(|| {
        msg(format!(
            "{what} `{name}`: use one of {}",
            T::names().collect::<Vec<_>>().join(", ")
        ))
    })
}

fn to_json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).expect("the library's records serialise")
}

/// A record as Python objects (dict, list, float, ...), without a JSON text
/// in between (parsing a stack's metadata in Python was a fifth of binning
/// a small file).
fn to_py<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    fn value<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
        use pyo3::types::PyList;
        Ok(match v {
            serde_json::Value::Null => py.None().into_bound(py),
            serde_json::Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
            serde_json::Value::Number(n) => match (n.as_i64(), n.as_u64()) {
                (Some(i), _) => i.into_pyobject(py)?.into_any(),
                (None, Some(u)) => u.into_pyobject(py)?.into_any(),
                _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
            },
            serde_json::Value::String(t) => t.into_pyobject(py)?.into_any(),
            serde_json::Value::Array(items) => {
                let list = PyList::empty(py);
                for item in items {
                    list.append(value(py, item)?)?;
                }
                list.into_any()
            }
            serde_json::Value::Object(map) => {
                let d = PyDict::new(py);
                for (k, item) in map {
                    d.set_item(k, value(py, item)?)?;
                }
                d.into_any()
            }
        })
    }
    value(
        py,
        &serde_json::to_value(v).expect("the library's records serialise"),
    )
}

/// Every tag of a recorded file as columns.
#[pyfunction]
fn read_tags<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let table = py
        .detach(|| scatterscope::tags::table::read_tags(&path))
        .map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("channel", PyArray1::from_vec(py, table.channel))?;
    d.set_item("macro_time", PyArray1::from_vec(py, table.macro_time))?;
    d.set_item("micro_time", PyArray1::from_vec(py, table.micro_time))?;
    d.set_item("marker_bits", PyArray1::from_vec(py, table.marker_bits))?;
    d.set_item("marker_time", PyArray1::from_vec(py, table.marker_time))?;
    d.set_item("sync_time", PyArray1::from_vec(py, table.sync_time))?;
    d.set_item("resolution_s", table.resolution_s)?;
    d.set_item("macro_unit_s", table.macro_unit_s)?;
    d.set_item("header", table.header)?;
    Ok(d)
}

/// Bins a recorded file: (stacks, metadata per stack, ledger, summary
/// lines).
#[pyfunction]
#[pyo3(signature = (path, bin_width_ps=None, t_start_ps=0.0, bins=None, channel=None, pixels="auto", frames="sum", allow_truncated=false, dtype=None, spc_module=None, micro_unit_ps=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn bin_file<'py>(
    py: Python<'py>,
    path: PathBuf,
    bin_width_ps: Option<f64>,
    t_start_ps: f64,
    bins: Option<usize>,
    channel: Option<u16>,
    pixels: &str,
    frames: &str,
    allow_truncated: bool,
    dtype: Option<&str>,
    spc_module: Option<&str>,
    micro_unit_ps: Option<f64>,
) -> PyResult<(
    Vec<Bound<'py, PyAny>>,
    Vec<Bound<'py, PyAny>>,
    Bound<'py, PyAny>,
    Vec<String>,
)> {
    let spec = BinSpec {
        bin_width_ps,
        t_start_ps,
        bins,
        channel,
        pixels: named::<Pixels>("pixels", pixels)?,
        frames: frames.parse::<FrameSelect>().map_err(msg)?,
        allow_truncated,
        spc: SpcOptions {
            module: spc_module
                .map(|m| named::<SpcModule>("spc_module", m))
                .transpose()?,
            micro_unit_ps,
        },
    };
    if !matches!(dtype, None | Some("float32" | "uint16" | "uint32")) {
        return Err(ScatterscopeError::new_err(format!(
            "bin_file: dtype {:?} is not one of float32, uint16, uint32",
            dtype.unwrap_or_default()
        )));
    }
    let binned = py
        .detach(|| lib_bin_file_counts(&path, &spec))
        .map_err(err)?;
    let summary = binned.summary();
    let ledger = to_py(py, &binned.counts)?;
    let mut arrays = Vec::new();
    let mut metas = Vec::new();
    for (frame, stack) in binned.stacks.into_iter().enumerate() {
        metas.push(to_py(py, &stack.meta)?);
        let too_large = |largest: u32, dtype: &str| {
            ScatterscopeError::new_err(format!(
                "bin_file: {}: stack {frame} holds {largest} photons in one bin, more than {dtype} holds exactly: ask for dtype=\"uint32\"",
                path.display()
            ))
        };
        arrays.push(match dtype {
            // The counts as binned: moved into numpy, not copied.
            Some("uint32") => stack.counts.into_pyarray(py).into_any(),
            Some("uint16") => stack
                .narrowed::<u16>()
                .map_err(|largest| too_large(largest, "uint16"))?
                .into_pyarray(py)
                .into_any(),
            _ => {
                let values = Stack::from_owned_counts(stack.counts, stack.meta);
                if let (Some(_), Some(exact)) = (dtype, &values.exact_counts) {
                    let largest = exact.iter().copied().max().unwrap_or(0);
                    return Err(too_large(largest, "float32"));
                }
                counts_array(py, values.data, values.exact_counts)
            }
        });
    }
    Ok((arrays, metas, ledger, summary))
}

/// A stack's values as numpy: float32, or uint32 when the counts do not
/// all fit float32 exactly (above 2^24).
fn counts_array<'py>(
    py: Python<'py>,
    data: ndarray::Array3<f32>,
    exact: Option<ndarray::Array3<u32>>,
) -> Bound<'py, PyAny> {
    match exact {
        Some(counts) => counts.into_pyarray(py).into_any(),
        None => data.into_pyarray(py).into_any(),
    }
}

/// A stack file's counts and metadata JSON (None for a plain array).
#[pyfunction]
fn load_stack<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyAny>, Option<String>)> {
    let file = py.detach(|| Stack::read_file(&path)).map_err(err)?;
    if let Some(m) = &file.meta {
        // The same checks as every reader of the library.
        Stack::from_parts(file.data.clone(), m.clone(), &path).map_err(err)?;
    }
    Ok((
        counts_array(py, file.data, file.exact_counts),
        file.meta.map(|m| to_json(&m)),
    ))
}

/// A 2-D image (EXR, PNG, npy, ...), e.g. a reconstruction.
#[pyfunction]
fn load_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let img = py
        .detach(|| scatterscope::formats::image::read_image(&path))
        .map_err(err)?;
    Ok(img.into_pyarray(py))
}

/// Writes counts with their metadata (JSON) as EXR, npy + JSON, or OME-TIFF
/// (a `.ome.tif` name: one page per bin, for Fiji, napari or FLIMfit).
#[pyfunction]
#[pyo3(signature = (path, data, meta_json, counts=None))]
fn save_stack(
    py: Python<'_>,
    path: PathBuf,
    data: PyReadonlyArray3<'_, f32>,
    meta_json: &str,
    counts: Option<PyReadonlyArray3<'_, u32>>,
) -> PyResult<()> {
    let meta: StackMeta = serde_json::from_str(meta_json)
        .map_err(|e| msg(format!("{}: the metadata: {e}", path.display())))?;
    let mut stack = Stack::from_parts(data.as_array().to_owned(), meta, &path).map_err(err)?;
    if let Some(c) = counts {
        // Whole counts given exactly: kept exactly when float32 cannot.
        stack.exact_counts = scatterscope::stack::exact_copy(c.as_array());
    }
    py.detach(|| stack.save(&path)).map_err(err)
}

/// Metadata JSON of measured counts in `bins` bins of `bin_width_ps` from
/// `t_start_ps` (no physics recorded).
#[pyfunction]
fn measured_meta(t_start_ps: f64, bin_width_ps: f64, bins: usize, source: String) -> String {
    to_json(&StackMeta::measured(
        t_start_ps,
        bin_width_ps,
        bins,
        source,
        None,
    ))
}

/// The ST-PSF kernels of the physics: (kernels (bins, rows, cols), bin
/// table JSON, the setup JSON).
#[pyfunction]
#[pyo3(signature = (sampling="integrated", **physics))]
fn psf_kernels<'py>(
    py: Python<'py>,
    sampling: &str,
    physics: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, String, String)> {
    let setup = overrides(physics)?.resolve().map_err(err)?;
    let sampling = named::<Sampling>("sampling", sampling)?;
    let k = py
        .detach(|| KernelStack::build(&setup, sampling))
        .map_err(err)?;
    let bins = to_json(&k.bins);
    let setup = to_json(&k.setup);
    Ok((k.kernels.into_pyarray(py), bins, setup))
}

/// Simulates an image: (counts, expected counts, metadata JSON of the
/// counts).
#[pyfunction]
#[pyo3(signature = (image, seed=0, boundary="sensor", **physics))]
#[allow(clippy::type_complexity)]
fn simulate<'py>(
    py: Python<'py>,
    image: PyReadonlyArray2<'py, f64>,
    seed: u64,
    boundary: &str,
    physics: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<f32>>, String)> {
    let mut o = overrides(physics)?;
    let truth: Array2<f64> = image.as_array().to_owned();
    let (h, w) = truth.dim();
    if h != w {
        return Err(msg(format!(
            "the image is {h} x {w}: the sensor is square (give a square image)"
        )));
    }
    o.size.get_or_insert(h);
    let setup = o.resolve().map_err(err)?;
    let boundary = named::<Boundary>("boundary", boundary)?;
    let sim = py
        .detach(|| {
            scatterscope::simulate::simulate_image(
                &setup,
                truth,
                Sampling::Integrated,
                boundary,
                seed,
                "an array from Python".into(),
            )
        })
        .map_err(err)?;
    Ok(simulated(py, sim.counts, sim.expected))
}

/// A simulation's stacks for Python: (counts, expected counts, metadata
/// JSON).
fn simulated(
    py: Python<'_>,
    counts: Stack,
    expected: Stack,
) -> (Bound<'_, PyArray3<f32>>, Bound<'_, PyArray3<f32>>, String) {
    let meta = to_json(&counts.meta);
    (
        counts.data.into_pyarray(py),
        expected.data.into_pyarray(py),
        meta,
    )
}

/// One case of the learned reconstruction's training, simulated as the
/// benchmark simulates (`image`, a square object grid larger than the
/// sensor of `sensor_px`, which sees its centre at the physics' pitch;
/// plus `background_share` times the mean expected count per pixel and
/// bin), the kernels discretised as `discretisation` says (`integrated`,
/// `point` or `half-pitch` with `offset`) and the light crossing
/// `true_physics`' medium when given (else the physics'): (the network's
/// inputs (channels, rows, columns), the truth on the sensor, a dict of the
/// inputs' scale, photons per pixel, blur width and background share, and
/// the data steps' operator: the time-summed counts, the time-summed kernel
/// on the model's grid (origin-centred), the sensor's offset on that grid,
/// the summed background per pixel and the last Richardson-Lucy iterate on
/// the grid). The inputs are computed by the function `reconstruct
/// --method learned` runs.
#[pyfunction]
#[pyo3(signature = (image, sensor_px, seed=0, background_share=0.0, discretisation="integrated", offset=(0, 0), true_physics=None, **physics))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn learned_case<'py>(
    py: Python<'py>,
    image: PyReadonlyArray2<'py, f64>,
    sensor_px: usize,
    seed: u64,
    background_share: f64,
    discretisation: &str,
    offset: (usize, usize),
    true_physics: Option<&Bound<'py, PyDict>>,
    physics: Option<&Bound<'py, PyDict>>,
) -> PyResult<(
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyDict>,
)> {
    use scatterscope::report::bench::{CaseSimulation, Discretisation};
    let mut o = overrides(physics)?;
    o.size = Some(sensor_px);
    let setup = o.resolve().map_err(err)?;
    let true_medium = match true_physics {
        Some(t) => {
            let mut o = overrides(Some(t))?;
            o.size = Some(sensor_px);
            Some(o.resolve().map_err(err)?.medium)
        }
        None => None,
    };
    let discretisation = match discretisation {
        "integrated" => Discretisation::Integrated,
        "point" => Discretisation::Point,
        "half-pitch" => Discretisation::HalfPitch { offset },
        other => {
            return Err(msg(format!(
                "discretisation `{other}`: use integrated, point or half-pitch"
            )));
        }
    };
    let how = CaseSimulation {
        background_share,
        discretisation,
        true_medium,
    };
    let object: Array2<f64> = image.as_array().to_owned();
    let done = py
        .detach(|| -> Result<_, String> {
            let case = scatterscope::report::bench::simulate_object(object, &setup, seed, &how)
                .map_err(|e| scatterscope::error_text(&e))?;
            let bins = case.problem.all_bins();
            let model = &case.problem.model;
            let data = scatterscope::reconstruct::Data::new(model, &case.problem.counts, &bins)
                .map_err(|e| scatterscope::error_text(&e))?;
            let inputs = scatterscope::reconstruct::learned::inputs::learned_inputs(&data)
                .ok_or_else(|| "no photons in the simulated stack".to_string())?;
            let summed = model.summed(&bins);
            let kernel = summed.fft().inverse(summed.spectrum(0).to_vec());
            let grid = model.grid_shape();
            let operator = (
                Array2::from_shape_vec(grid, kernel).expect("the model's grid"),
                model.sensor_offset(),
                model.background() * bins.len() as f64,
                case.problem.counts.sum_axis(ndarray::Axis(0)),
            );
            Ok((inputs, case.truth, operator))
        })
        .map_err(msg)?;
    let (inputs, truth, (kernel, sensor_offset, background, counts)) = done;
    let facts = PyDict::new(py);
    facts.set_item("scale", inputs.scale)?;
    facts.set_item("photons_per_pixel", inputs.photons_per_pixel)?;
    facts.set_item("kernel_width_px", inputs.kernel_width_px)?;
    facts.set_item("background_share", inputs.background_share)?;
    facts.set_item("counts", counts.into_pyarray(py))?;
    let base = Array2::from_shape_vec(kernel.dim(), inputs.base_grid).expect("the model's grid");
    facts.set_item("kernel", kernel.into_pyarray(py))?;
    facts.set_item("sensor_offset", sensor_offset)?;
    facts.set_item("background", background)?;
    facts.set_item("base_grid", base.into_pyarray(py))?;
    Ok((
        inputs.features.into_pyarray(py),
        truth.into_pyarray(py),
        facts,
    ))
}

/// Per-pixel decay maps of a stack of counts (bins, rows, columns) whose
/// bins start at `bin_starts_ps`: a dict of float64 maps (NaN where
/// masked), the mask, onset, frequency and notes, as `scatterscope
/// lifetime` writes them.
#[pyfunction]
#[pyo3(signature = (counts, bin_starts_ps, bin_width_ps, frequency_hz, harmonics=vec![1, 2], min_photons=20.0, onset_ps=None, reference_phasors=None, reference_lifetime_ps=0.0))]
#[allow(clippy::too_many_arguments)]
fn decay_maps<'py>(
    py: Python<'py>,
    counts: Bound<'py, PyAny>,
    bin_starts_ps: Vec<f64>,
    bin_width_ps: f64,
    frequency_hz: f64,
    harmonics: Vec<u32>,
    min_photons: f64,
    onset_ps: Option<f64>,
    reference_phasors: Option<Vec<(f64, f64)>>,
    reference_lifetime_ps: f64,
) -> PyResult<Bound<'py, PyDict>> {
    use scatterscope::decay::{DecayOptions, Onset, Reference};
    let options = DecayOptions {
        harmonics,
        min_photons,
        onset: onset_ps.map_or(Onset::HalfMaximum, Onset::At),
        reference: reference_phasors.map(|phasors| Reference {
            phasors,
            lifetime_ps: reference_lifetime_ps,
            what: "the given reference phasors".into(),
        }),
    };
    use scatterscope::stack::CountsView;
    let counted = |v: CountsView<'_>| {
        scatterscope::decay::decay_maps(v, &bin_starts_ps, bin_width_ps, frequency_hz, &options)
    };
    let maps = if let Ok(a) = counts.extract::<PyReadonlyArray3<'py, u16>>() {
        let v = a.as_array();
        py.detach(|| counted(CountsView::U16(v)))
    } else if let Ok(a) = counts.extract::<PyReadonlyArray3<'py, u32>>() {
        let v = a.as_array();
        py.detach(|| counted(CountsView::U32(v)))
    } else if let Ok(a) = counts.extract::<PyReadonlyArray3<'py, f32>>() {
        let v = a.as_array();
        py.detach(|| {
            scatterscope::decay::decay_maps_f32(v, &bin_starts_ps, bin_width_ps, frequency_hz, &options)
        })
    } else {
        return Err(msg(
            "decay_maps: counts must be a 3-D numpy array (bins, rows, columns) of uint16, uint32 or float32",
        ));
    }
    .map_err(|e| msg(format!("decay_maps: {e}")))?;
    let d = PyDict::new(py);
    d.set_item("photons", maps.intensity.into_pyarray(py))?;
    d.set_item("mean_time_ps", maps.mean_time_ps.into_pyarray(py))?;
    d.set_item("variance_ps2", maps.variance_ps2.into_pyarray(py))?;
    d.set_item("fast_lifetime_ps", maps.fast_lifetime_ps.into_pyarray(py))?;
    d.set_item(
        "fast_lifetime_centred_ps",
        maps.fast_lifetime_centred_ps.into_pyarray(py),
    )?;
    for p in maps.phasors {
        let h = p.harmonic;
        d.set_item(format!("g{h}"), p.g.into_pyarray(py))?;
        d.set_item(format!("s{h}"), p.s.into_pyarray(py))?;
        if let Some(c) = p.calibrated {
            d.set_item(format!("g{h}_calibrated"), c.g.into_pyarray(py))?;
            d.set_item(format!("s{h}_calibrated"), c.s.into_pyarray(py))?;
            d.set_item(
                format!("phase_lifetime{h}_ps"),
                c.tau_phase_ps.into_pyarray(py),
            )?;
            d.set_item(
                format!("modulation_lifetime{h}_ps"),
                c.tau_modulation_ps.into_pyarray(py),
            )?;
        }
    }
    d.set_item("mask", maps.mask.into_pyarray(py))?;
    d.set_item("onset_ps", maps.onset_ps)?;
    d.set_item("frequency_hz", maps.frequency_hz)?;
    d.set_item("notes", maps.notes)?;
    Ok(d)
}

/// Lifetimes fitted pixel by pixel (or globally) in a stack of counts
/// (bins, rows, columns) whose bins start at `bin_starts_ps`, as
/// `scatterscope fit` fits them: a dict of float64 maps (NaN where
/// masked), the mask, the summed decay's fit and the notes.
#[pyfunction]
#[pyo3(signature = (counts, bin_starts_ps, bin_width_ps, frequency_hz=None, components=1, irf="edge", irf_decay=None, least_squares=false, binning=0, min_photons=100.0, global_fit=false, window=None, incomplete_decay=true, fit_irf_shift=false, recorded=None))]
#[allow(clippy::too_many_arguments)]
fn fit_lifetimes<'py>(
    py: Python<'py>,
    counts: Bound<'py, PyAny>,
    bin_starts_ps: Vec<f64>,
    bin_width_ps: f64,
    frequency_hz: Option<f64>,
    components: usize,
    irf: &str,
    irf_decay: Option<Vec<f64>>,
    least_squares: bool,
    binning: usize,
    min_photons: f64,
    global_fit: bool,
    window: Option<(usize, usize)>,
    incomplete_decay: bool,
    fit_irf_shift: bool,
    recorded: Option<(usize, usize)>,
) -> PyResult<Bound<'py, PyDict>> {
    use scatterscope::decay::fit::optimise::Objective;
    use scatterscope::decay::fit::{FitOptions, IrfSource, fit_maps};
    use scatterscope::stack::CountsView;
    let irf = match (irf, irf_decay) {
        ("measured", Some(decay)) => IrfSource::Measured {
            decay,
            what: "the given IRF".into(),
        },
        ("gaussian", None) => IrfSource::Gaussian,
        ("edge", None) => IrfSource::RisingEdge,
        ("none", None) => IrfSource::Tail,
        (other, d) => {
            return Err(msg(format!(
                "fit_lifetimes: irf `{other}`{}: give an IRF array (irf=\"measured\"), or \"gaussian\", \"edge\" or \"none\" without one",
                if d.is_some() {
                    " with an IRF array"
                } else {
                    ""
                }
            )));
        }
    };
    if let Some(f) = frequency_hz {
        scatterscope::tags::laser::given(f)
            .map_err(|e| msg(format!("fit_lifetimes: frequency_hz: {e}")))?;
    }
    let options = FitOptions {
        components,
        irf,
        objective: if least_squares {
            Objective::LeastSquares
        } else {
            Objective::Poisson
        },
        binning,
        min_photons,
        global: global_fit,
        window,
        recorded,
        incomplete_decay,
        fit_irf_shift,
        kernel: Default::default(),
    };
    let fitted =
        |v: CountsView<'_>| fit_maps(v, &bin_starts_ps, bin_width_ps, frequency_hz, &options);
    let maps = if let Ok(a) = counts.extract::<PyReadonlyArray3<'py, u16>>() {
        let v = a.as_array();
        py.detach(|| fitted(CountsView::U16(v)))
    } else if let Ok(a) = counts.extract::<PyReadonlyArray3<'py, u32>>() {
        let v = a.as_array();
        py.detach(|| fitted(CountsView::U32(v)))
    } else {
        return Err(msg(
            "fit_lifetimes: counts must be a 3-D numpy array (bins, rows, columns) of uint16 or uint32",
        ));
    }
    .map_err(|e| msg(format!("fit_lifetimes: {e}")))?;
    let d = PyDict::new(py);
    d.set_item("photons", maps.photons.into_pyarray(py))?;
    for (k, t) in maps.lifetimes_ps.into_iter().enumerate() {
        d.set_item(format!("tau{}_ps", k + 1), t.into_pyarray(py))?;
    }
    for (k, t) in maps.lifetime_errors_ps.into_iter().enumerate() {
        d.set_item(format!("tau{}_error_ps", k + 1), t.into_pyarray(py))?;
    }
    for (k, t) in maps.amplitudes.into_iter().enumerate() {
        d.set_item(format!("a{}", k + 1), t.into_pyarray(py))?;
    }
    for (k, t) in maps.amplitude_fractions.into_iter().enumerate() {
        d.set_item(format!("a{}_fraction", k + 1), t.into_pyarray(py))?;
    }
    for (k, t) in maps.intensity_fractions.into_iter().enumerate() {
        d.set_item(format!("intensity_fraction{}", k + 1), t.into_pyarray(py))?;
    }
    d.set_item("tau_amplitude_ps", maps.tau_amplitude_ps.into_pyarray(py))?;
    d.set_item("tau_intensity_ps", maps.tau_intensity_ps.into_pyarray(py))?;
    d.set_item("background", maps.background.into_pyarray(py))?;
    d.set_item("reduced_chi2", maps.reduced_chi2.into_pyarray(py))?;
    d.set_item("deviance", maps.deviance.into_pyarray(py))?;
    d.set_item("mask", maps.mask.into_pyarray(py))?;
    d.set_item("summed_decay", maps.summed.decay)?;
    d.set_item("summed_fit", maps.summed.fit)?;
    d.set_item("summed_params", maps.summed.params)?;
    d.set_item("window", maps.summed.window)?;
    d.set_item("notes", maps.notes)?;
    Ok(d)
}

/// Simulates a built-in scene or an image file (as `scatterscope
/// simulate --scene`): (counts, expected counts, metadata JSON, truth).
#[pyfunction]
#[pyo3(signature = (scene, seed=0, boundary="sensor", **physics))]
#[allow(clippy::type_complexity)]
fn simulate_scene<'py>(
    py: Python<'py>,
    scene: &str,
    seed: u64,
    boundary: &str,
    physics: Option<&Bound<'py, PyDict>>,
) -> PyResult<(
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray3<f32>>,
    String,
    Bound<'py, PyArray2<f64>>,
)> {
    let setup = overrides(physics)?.resolve().map_err(err)?;
    let boundary = named::<Boundary>("boundary", boundary)?;
    let scene = scatterscope::scene::Scene::parse(scene);
    let sim = py
        .detach(|| {
            scatterscope::simulate::simulate(&setup, &scene, Sampling::Integrated, boundary, seed)
        })
        .map_err(err)?;
    let (counts, expected, meta) = simulated(py, sim.counts, sim.expected);
    Ok((counts, expected, meta, sim.truth.into_pyarray(py)))
}

/// Reconstructs counts: (image, trace JSON, notes).
#[pyfunction]
#[pyo3(signature = (data, meta_json=None, method="auto", bin=None, boundary=None, background="auto", denoiser="ffdnet", weights=None, tv_gain=0.5, solver="split", max_iters=None, learned_weights=None, **physics))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn reconstruct<'py>(
    py: Python<'py>,
    data: PyReadonlyArray3<'py, f32>,
    meta_json: Option<&str>,
    method: &str,
    bin: Option<usize>,
    boundary: Option<&str>,
    background: &str,
    denoiser: &str,
    weights: Option<PathBuf>,
    tv_gain: f64,
    solver: &str,
    max_iters: Option<usize>,
    learned_weights: Option<PathBuf>,
    physics: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, String, Vec<String>)> {
    let meta: Option<StackMeta> = meta_json
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| msg(format!("the metadata: {e}")))?;
    let spec = InputSpec {
        physics: overrides(physics)?,
        fit_physics: None,
        boundary: boundary
            .map(|b| named::<Boundary>("boundary", b))
            .transpose()?,
        background: BackgroundChoice::parse(background).map_err(msg)?,
    };
    let method = named::<Method>("method", method)?;
    if method.needs_bin() && bin.is_none() {
        return Err(msg(format!("method {} needs bin=K", method.name())));
    }
    let prior = PriorSpec {
        kind: named::<PriorKind>("denoiser", denoiser)?,
        weights,
        tv_gain,
    };
    let mut opts = MethodOptions {
        solver: named::<Solver>("solver", solver)?,
        learned: learned_weights
            .map(|p| scatterscope::reconstruct::learned::from_file(&p))
            .transpose()
            .map_err(|e| msg(e.to_string()))?,
        ..MethodOptions::default()
    };
    if let Some(cap) = max_iters {
        opts.cap_pnp_iters(cap);
    }
    // Checked before the copy: an array past the budget is refused, not
    // copied (the copy alone could end the interpreter).
    scatterscope::memory::check(
        scatterscope::memory::bytes_of(
            data.shape().iter().copied(),
            4 + scatterscope::memory::PROBLEM_BYTES,
        ),
        || format!("reconstructing an array of shape {:?}", data.shape()),
    )
    .map_err(err)?;
    let data: Array3<f32> = data.as_array().to_owned();
    let cancel = Arc::new(AtomicBool::new(false));
    let watch = cancel.clone();
    let done = interruptible(py, cancel, move || -> Result<_, String> {
        let text = |e: &dyn std::error::Error| scatterscope::error_text(e);
        let input =
            prepare(data, meta, Path::new("<array from Python>"), &spec).map_err(|e| text(&e))?;
        let denoiser = prior.build().map_err(|e| text(&e))?;
        let mut result = run_method(
            &input.problem,
            method,
            bin,
            denoiser.as_ref(),
            &opts,
            None,
            |_| {
                if watch.load(Ordering::Relaxed) {
                    std::panic::resume_unwind(Box::new(Cancelled));
                }
            },
        )
        .map_err(|e| text(&e))?;
        // As the CLI's record: what was assumed first, then the method's.
        result.trace.notes.splice(0..0, input.assumed);
        let mut notes = input.warnings;
        notes.extend(result.trace.notes.iter().cloned());
        Ok((result.image, to_json(&result.trace), notes))
    })?;
    let (image, trace, notes) = done.map_err(msg)?;
    Ok((image.into_pyarray(py), trace, notes))
}

/// The request for `device` into `out`: the library's defaults (the
/// command's), the acquisition settings among `kw` over them, the rest of
/// `kw` as the physics.
fn acquisition_request(
    py: Python<'_>,
    device: &str,
    out: PathBuf,
    duration_s: Option<f64>,
    kw: Option<&Bound<'_, PyDict>>,
) -> PyResult<scatterscope::acquire::request::Request> {
    use scatterscope::acquire::TimeZero;
    use scatterscope::acquire::request::{Request, parse_edge, parse_scan};
    let device = device
        .parse()
        .map_err(|e: String| msg(format!("device `{device}`: {e}")))?;
    let mut r = Request::new(device, out);
    r.software = format!("scatterscope python {}", env!("CARGO_PKG_VERSION"));
    if let Some(d) = duration_s {
        if !(d.is_finite() && d >= 0.0) {
            return Err(msg(format!(
                "duration_s = {d}: give a number of seconds >= 0 (0: until the device stops)"
            )));
        }
        r.duration = Some(Duration::try_from_secs_f64(d).map_err(|_| {
            msg(format!(
                "duration_s = {d}: longer than any acquisition can run"
            ))
        })?);
    }
    let physics = PyDict::new(py);
    let text = |v: &Bound<'_, PyAny>| v.extract::<String>();
    let edge = |v: &Bound<'_, PyAny>| -> PyResult<bool> {
        parse_edge(&v.extract::<String>()?).map_err(msg)
    };
    let (m, p) = (&mut r.mock, &mut r.picoquant);
    for (key, value) in kw.into_iter().flat_map(|k| k.iter()) {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        match key.as_str() {
            "scene" => m.scene = scatterscope::scene::Scene::parse(&text(&value)?),
            "rate_hz" => m.rate_hz = value.extract()?,
            "dark_rate_hz" => m.dark_rate_hz = value.extract()?,
            "afterpulse" => m.afterpulse_probability = value.extract()?,
            "seed" => m.seed = value.extract()?,
            "mock_delay_ps" => m.t0_delay_ps = value.extract()?,
            "max_photons" => m.max_photons = value.extract()?,
            "unpaced" => m.real_time = !value.extract::<bool>()?,
            "replay_batches" => m.replay_batches = value.extract()?,
            "faults" => m.faults = text(&value)?.parse().map_err(msg)?,
            "t0_ps" => r.t0 = TimeZero::At(value.extract()?),
            "t0_from" => r.t0 = TimeZero::FromReference(PathBuf::from(text(&value)?)),
            "roi" => r.region = Some(text(&value)?.parse().map_err(msg)?),
            "micro_time_unit_ps" => r.micro_time_unit_ps = Some(value.extract()?),
            "tags" => r.tags = Some(PathBuf::from(text(&value)?)),
            "speed" => r.speed = value.extract()?,
            "ome_tiff" => r.ome_tiff = value.extract()?,
            "vendor_lib" => p.library = Some(PathBuf::from(text(&value)?)),
            "sync_divider" => p.sync_divider = Some(value.extract()?),
            "sync_level_mv" => p.sync_level_mv = Some(value.extract()?),
            "sync_edge" => p.sync_rising = Some(edge(&value)?),
            "marker_edge" => p.markers_rising = Some(edge(&value)?),
            "sync_zero_cross_mv" => p.sync_zero_cross_mv = Some(value.extract()?),
            "sync_offset_ps" => p.sync_offset_ps = Some(value.extract()?),
            "input_level_mv" => p.input_level_mv = Some(value.extract()?),
            "input_edge" => p.input_rising = Some(edge(&value)?),
            "input_zero_cross_mv" => p.input_zero_cross_mv = Some(value.extract()?),
            "input_offsets_ps" => p.input_offsets_ps = value.extract()?,
            "binning" => p.binning = Some(value.extract()?),
            "t3_offset_ps" => p.t3_offset_ps = Some(value.extract()?),
            "scan" => p.scan = Some(parse_scan(&text(&value)?).map_err(msg)?),
            "channel" => p.channel = Some(value.extract()?),
            "pixels" => p.pixels = named("pixels", &text(&value)?)?,
            "ptu" => p.ptu = Some(PathBuf::from(text(&value)?)),
            "no_ptu" => p.no_ptu = value.extract()?,
            _ => physics.set_item(key, value)?,
        }
    }
    r.physics = overrides(Some(&physics))?;
    Ok(r)
}

/// Acquires from `device` (as `scatterscope acquire --device` names it)
/// into `out`, with the command's defaults, refusals and outputs: (stack,
/// metadata JSON, record JSON, summary lines).
#[pyfunction]
#[pyo3(signature = (device, out, duration_s=None, **settings))]
#[allow(clippy::type_complexity)]
fn acquire<'py>(
    py: Python<'py>,
    device: &str,
    out: PathBuf,
    duration_s: Option<f64>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, String, String, Vec<String>)> {
    let (job, _) = acquisition_request(py, device, out, duration_s, settings)?
        .job()
        .map_err(err)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let done = interruptible(py, stop, move || {
        job.run(&flag, |_| {})
            .map_err(|e| scatterscope::error_text(&e))
    })?
    .map_err(msg)?;
    let record = done
        .files
        .iter()
        .find(|f| f.ends_with("acquisition.json"))
        .and_then(|f| std::fs::read_to_string(f).ok())
        .unwrap_or_else(|| "{}".into());
    let summary = done.summary();
    let meta = to_json(&done.stack.meta);
    Ok((done.stack.data.into_pyarray(py), meta, record, summary))
}

/// One histogram argument: a file (MATLAB, stack, tag file) or a 1-D
/// array of counts with bins of `bin_width_ps`.
fn histogram(
    value: &Bound<'_, PyAny>,
    dataset: &str,
    bin_width_ps: Option<f64>,
    label: &str,
) -> PyResult<TimeHistogram> {
    if let Ok(path) = value.extract::<PathBuf>() {
        return TimeHistogram::read(&path, dataset, bin_width_ps).map_err(err);
    }
    let counts: Vec<f64> = value
        .extract::<numpy::PyReadonlyArray1<'_, f64>>()
        .map(|a| a.as_array().to_vec())
        .or_else(|_| value.extract::<Vec<f64>>())
        .map_err(|_| {
            msg(format!(
                "{label}: give a file path or a 1-D array of counts"
            ))
        })?;
    let width = bin_width_ps
        .ok_or_else(|| msg(format!("{label}: an array of counts needs bin_width_ps")))?;
    TimeHistogram::new(counts, width, 0.0, Path::new(label)).map_err(err)
}

/// The old parameter names among `names`, each with its new one (the
/// library's list, so the package warns for the names the command notes).
#[pyfunction]
fn renamed_parameters(names: Vec<String>) -> Vec<(&'static str, &'static str)> {
    scatterscope::calibrate::renamed_in(&names)
}

/// Fits a slab's mu_a and mu_s' to transmittance captures: (result JSON
/// with the estimates, lines, material.toml text).
#[pyfunction]
#[pyo3(signature = (reference, captures, refractive_index, predict=Vec::new(), bin_width_ps=None, dataset="out", irf_extent="period", mu_a=SlabFitOptions::START_MU_A_PER_CM, mu_s_reduced=SlabFitOptions::START_MU_S_REDUCED_PER_CM, fit=vec!["mu_a".to_string(), "mu_s_reduced".to_string()], offset_cm=0.0, rising_edge_share=RISING_EDGE_CONVENTION))]
#[allow(clippy::too_many_arguments)]
fn calibrate_slab<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    captures: Vec<(Bound<'py, PyAny>, f64)>,
    refractive_index: f64,
    predict: Vec<(Bound<'py, PyAny>, f64)>,
    bin_width_ps: Option<f64>,
    dataset: &str,
    irf_extent: &str,
    mu_a: f64,
    mu_s_reduced: f64,
    fit: Vec<String>,
    offset_cm: f64,
    rising_edge_share: f64,
) -> PyResult<String> {
    let reference = histogram(reference, dataset, bin_width_ps, "reference")?;
    let read = |list: &[(Bound<'py, PyAny>, f64)], what: &str| -> PyResult<Vec<Capture>> {
        list.iter()
            .enumerate()
            .map(|(i, (h, thickness_cm))| {
                let label = match h.extract::<PathBuf>() {
                    Ok(p) => p
                        .file_stem()
                        .map_or(format!("{what} {i}"), |s| s.to_string_lossy().into_owned()),
                    Err(_) => format!("{what} {i}"),
                };
                Ok(Capture {
                    histogram: histogram(h, dataset, bin_width_ps, &label)?,
                    thickness_cm: *thickness_cm,
                    label,
                })
            })
            .collect()
    };
    let fitted = read(&captures, "capture")?;
    let held = read(&predict, "predicted")?;
    let mut options = SlabFitOptions {
        refractive_index,
        mu_a_per_cm: mu_a,
        mu_s_reduced_per_cm: mu_s_reduced,
        fit_mu_a: false,
        fit_mu_s_reduced: false,
        offset_cm,
        fit_offset: false,
        rising_edge_share,
    };
    options.free_named(&fit).map_err(err)?;
    let extent = named::<IrfExtent>("irf_extent", irf_extent)?;
    let done = py
        .detach(|| lib_calibrate_slab(&reference, extent, fitted, held, &options, Vec::new()))
        .map_err(err)?;
    let f = &done.fit;
    let est = |e: &scatterscope::calibrate::transmittance::MediumEstimate| serde_json::json!({"value": e.value, "standard_error": e.standard_error, "fitted": e.fitted});
    let out = serde_json::json!({
        "mu_a_per_cm": est(&f.mu_a),
        "mu_s_reduced_per_cm": est(&f.mu_s_reduced),
        "offset_cm": est(&f.offset),
        "refractive_index": f.refractive_index,
        "chi2_per_dof": f.chi2_per_dof,
        "seconds": done.seconds,
        "lines": done.lines(),
        "material_toml": done.material_toml(),
    });
    Ok(out.to_string())
}

/// The numeric array `name` (or the only one) of a MATLAB (level 5 or
/// v7.3) or `.npy` file, in the file's own dimensions.
#[pyfunction]
#[pyo3(signature = (path, name=None))]
fn load_array<'py>(
    py: Python<'py>,
    path: PathBuf,
    name: Option<&str>,
) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
    let a = scatterscope::formats::lab_array::pick(&path, name, "array", |_| true)
        .map_err(|e| msg(format!("{}: {e}", path.display())))?;
    Ok(a.values.into_pyarray(py))
}

/// Reconstructs an object inside the medium from a SPAD camera's cube
/// (bins, rows, columns; any sign): (transmission, beam, used pixels,
/// report JSON), as `scatterscope embedded`.
#[pyfunction]
#[pyo3(signature = (cube, pitch_cm, bin_width_ps, front_thickness_cm, back_thickness_cm, mu_s_reduced, mu_a, refractive_index, beam="plane", beam_centre="0cm,0cm", time_zero_ps=None, fit_scattering=false, fit_absorption=false, time_groups=scatterscope::embedded::DEFAULT_TIME_GROUPS, max_iters=scatterscope::embedded::DEFAULT_MAX_ITERS, iterations=None, mask=None, subtracted_background=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn reconstruct_embedded<'py>(
    py: Python<'py>,
    cube: PyReadonlyArray3<'py, f64>,
    pitch_cm: (f64, f64),
    bin_width_ps: f64,
    front_thickness_cm: f64,
    back_thickness_cm: f64,
    mu_s_reduced: f64,
    mu_a: f64,
    refractive_index: f64,
    beam: &str,
    beam_centre: &str,
    time_zero_ps: Option<f64>,
    fit_scattering: bool,
    fit_absorption: bool,
    time_groups: usize,
    max_iters: usize,
    iterations: Option<usize>,
    mask: Option<PyReadonlyArray2<'py, bool>>,
    subtracted_background: Option<f64>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<bool>>,
    String,
)> {
    use scatterscope::embedded::{self, noise::Subtracted, request::GeometryArgs};
    let geometry = GeometryArgs {
        front_thickness_cm,
        back_thickness_cm,
        mu_s_reduced_per_cm: mu_s_reduced,
        mu_a_per_cm: mu_a,
        refractive_index,
        back_mu_s_reduced_per_cm: None,
        back_mu_a_per_cm: None,
        beam: beam.to_string(),
        beam_centre: beam_centre.to_string(),
    }
    .geometry(None)
    .map_err(msg)?;
    scatterscope::memory::check(
        scatterscope::memory::bytes_of(cube.shape().iter().copied(), embedded::CUBE_BYTES),
        || format!("reconstructing a cube of shape {:?}", cube.shape()),
    )
    .map_err(err)?;
    let cube =
        embedded::cube::from_values(cube.as_array().to_owned(), pitch_cm, "array").map_err(msg)?;
    let settings = embedded::Settings {
        geometry,
        bin_width_ps,
        time_zero_ps,
        fit_media: embedded::calibrate::Free {
            scattering: fit_scattering,
            absorption: fit_absorption,
        },
        time_groups,
        max_iters,
        iterations,
        subtracted: subtracted_background.map(Subtracted::Level),
        mask: mask.map(|m| m.as_array().mapv(|bad| !bad)),
    };
    let done = py
        .detach(|| embedded::reconstruct(&cube, &settings))
        .map_err(err)?;
    let report = serde_json::to_string(&done.report).map_err(err)?;
    Ok((
        done.transmission.into_pyarray(py),
        done.beam.into_pyarray(py),
        done.used.into_pyarray(py),
        report,
    ))
}

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    scatterscope::cache::use_default();
    m.add("ScatterscopeError", m.py().get_type::<ScatterscopeError>())?;
    m.add_function(wrap_pyfunction!(read_tags, m)?)?;
    m.add_function(wrap_pyfunction!(bin_file, m)?)?;
    m.add_function(wrap_pyfunction!(load_stack, m)?)?;
    m.add_function(wrap_pyfunction!(save_stack, m)?)?;
    m.add_function(wrap_pyfunction!(load_image, m)?)?;
    m.add_function(wrap_pyfunction!(measured_meta, m)?)?;
    m.add_function(wrap_pyfunction!(psf_kernels, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_scene, m)?)?;
    m.add_function(wrap_pyfunction!(learned_case, m)?)?;
    m.add_function(wrap_pyfunction!(decay_maps, m)?)?;
    m.add_function(wrap_pyfunction!(fit_lifetimes, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(acquire, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_slab, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_embedded, m)?)?;
    m.add_function(wrap_pyfunction!(load_array, m)?)?;
    m.add_function(wrap_pyfunction!(renamed_parameters, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
