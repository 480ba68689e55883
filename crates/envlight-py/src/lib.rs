//! The `envlight._native` Python module: the library's environment light, its
//! product sampler and its verification harness over numpy arrays.
//!
//! Arrays come in as `float32` and are read in place when C-contiguous (copied
//! otherwise); results are new `float32` arrays. Every batch call releases the
//! interpreter lock and goes through the library's batch kernels. Errors become
//! the Python exception a user expects (`FileNotFoundError`, `OSError`,
//! `ValueError`, `TypeError`); nothing panics across the boundary.

use std::sync::{Arc, OnceLock};

mod visibility;

use envlight::gpu::RadianceFormat;
use envlight::light::{Density, Mapping, NamedOption, OptionError, Sampler};
use envlight::load::{load, LoadOptions};
use envlight::portal::{Portal, PortalLight, PortalOptions};
use envlight::{
    EnvImage, Factor, LightOptions, Lookup, ProductOptions, ProductSampler, Rotation, Vec3,
};
use envlight_verify::{AtShadingPoint, Config, Integrand, Lobes, Reference, SphereSampler};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rayon::prelude::*;

/// The world frame directions are given and returned in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Frame {
    /// The library's: z up.
    ZUp,
    /// Mitsuba 3's envmap frame (docs/design.md §6b): `(y, z, −x)` of the z-up direction.
    YUp,
}

impl Frame {
    fn parse(name: &str) -> PyResult<Self> {
        match name {
            "z-up" => Ok(Frame::ZUp),
            "y-up" => Ok(Frame::YUp),
            _ => Err(PyValueError::new_err(format!(
                "frame must be \"z-up\" or \"y-up\", not {name:?}"
            ))),
        }
    }

    /// A z-up direction in this frame.
    fn z_up_to_frame(self, d: Vec3) -> Vec3 {
        match self {
            Frame::ZUp => d,
            Frame::YUp => Vec3::new(d.y, d.z, -d.x),
        }
    }

    /// A direction in this frame, in z-up.
    fn frame_to_z_up(self, d: Vec3) -> Vec3 {
        match self {
            Frame::ZUp => d,
            Frame::YUp => Vec3::new(-d.z, d.x, d.y),
        }
    }
}

/// The light's keyword arguments, as `EnvironmentLight()` and `from_array` take
/// them.
struct LightKeywords<'a> {
    sampler: &'a str,
    density: Option<&'a str>,
    mapping: Option<&'a str>,
    input_mapping: &'a str,
    lookup: &'a str,
    rotate: f32,
    scale: f32,
    table_width: Option<usize>,
    equal_area_size: Option<usize>,
    mis_compensation: bool,
}

impl LightKeywords<'_> {
    /// The light's options, checked by the library ([`LightOptions::validate`]);
    /// `ValueError` naming the keyword for an unknown name or a refused option.
    fn options(&self) -> PyResult<LightOptions> {
        let sampler = choose::<Sampler>("sampler", self.sampler)?;
        // No density given: the library's default for the sampler and table.
        let density = match self.density {
            Some(density) => choose::<Density>("density", density)?,
            None => Density::default_for(sampler, self.table_width),
        };
        let input_mapping = choose::<Mapping>("input_mapping", self.input_mapping)?;
        // No mapping given: the input's own, so an equal-area square is lit as one.
        let mapping = match self.mapping {
            Some(mapping) => choose::<Mapping>("mapping", mapping)?,
            None => input_mapping,
        };
        let options = LightOptions {
            sampler,
            density,
            mapping,
            input_mapping,
            lookup: choose("lookup", self.lookup)?,
            rotation: Rotation::about_z_degrees(self.rotate),
            scale: self.scale,
            table_width: self.table_width,
            equal_area_size: self.equal_area_size,
            mis_compensation: self.mis_compensation,
        };
        options.validate().map_err(|e| option_error(&e))?;
        Ok(options)
    }
}

/// The `ValueError` for options the library refuses, naming the keyword.
fn option_error(e: &OptionError) -> PyErr {
    let keyword = match e.field() {
        "rotation" => "rotate",
        field => field,
    };
    PyValueError::new_err(format!("{keyword}: {e}"))
}

/// The value of the option `T` named `value`, or a `ValueError` naming the
/// keyword and listing the accepted names.
fn choose<T: NamedOption>(keyword: &'static str, value: &str) -> PyResult<T> {
    T::from_name(value).map_err(|mut e| {
        e.option = keyword;
        PyValueError::new_err(e.to_string())
    })
}

/// `ValueError` unless the arrays `a` and `b` have the same number of rows.
fn same_length(a: &str, a_rows: usize, b: &str, b_rows: usize) -> PyResult<()> {
    if a_rows == b_rows {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{a} and {b} must have the same length, not {a_rows} and {b_rows}"
        )))
    }
}

/// The Python exception for a library error.
fn to_py_err(e: envlight::Error) -> PyErr {
    match &e {
        envlight::Error::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        envlight::Error::Io { .. }
        | envlight::Error::UnsupportedFormat { .. }
        | envlight::Error::Decode { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// The rows of an `(N, K)` float32 array as a slice of `N·K` values, borrowed
/// when C-contiguous, copied otherwise; `TypeError`/`ValueError` naming `what`
/// and the expected shape when it is not `(N, K)`.
fn rows<'a, const K: usize>(
    array: &'a PyReadonlyArray2<'_, f32>,
    what: &str,
) -> PyResult<std::borrow::Cow<'a, [f32]>> {
    let shape = array.shape();
    if shape[1] != K {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (N, {K}), not {shape:?}"
        )));
    }
    // `as_slice` also accepts Fortran order, whose memory order is not the rows'.
    Ok(match array.as_slice() {
        Ok(s) if array.is_c_contiguous() => std::borrow::Cow::Borrowed(s),
        _ => std::borrow::Cow::Owned(array.as_array().iter().copied().collect()),
    })
}

/// `values` (`N·K` floats) viewed as `N` arrays of `K`.
fn as_arrays<const K: usize>(values: &[f32]) -> &[[f32; K]] {
    // SAFETY: `[f32; K]` has the size and alignment of `K` consecutive `f32`, and
    // the length is a multiple of `K` (checked by `rows`).
    unsafe { std::slice::from_raw_parts(values.as_ptr().cast::<[f32; K]>(), values.len() / K) }
}

/// The z-up directions of an `(N, 3)` array in `frame`, borrowed where nothing
/// needs converting.
fn directions<'a>(values: &'a [f32], frame: Frame) -> std::borrow::Cow<'a, [Vec3]> {
    // SAFETY: `Vec3` is `repr(C)` over three `f32`.
    let view: &[Vec3] =
        unsafe { std::slice::from_raw_parts(values.as_ptr().cast::<Vec3>(), values.len() / 3) };
    match frame {
        Frame::ZUp => std::borrow::Cow::Borrowed(view),
        Frame::YUp => {
            std::borrow::Cow::Owned(view.iter().map(|&d| frame.frame_to_z_up(d)).collect())
        }
    }
}

/// Output buffers of the batch calls, kept for reuse when their arrays die.
///
/// A fresh multi-megabyte buffer costs its pages' first-touch faults (the kernel
/// zeroes every 4 KiB page as the batch writes it): 1-2 ns per query measured on
/// the peer harness, a fifth of a batch pdf's time. Dr.Jit keeps freed buffers
/// for the same reason. A batch output of at least [`POOLED_MIN`] floats lives
/// in a buffer from here, and goes back here when numpy frees its array; the
/// pool holds at most [`POOL_BUFFERS`] buffers and [`POOL_BYTES`] bytes, and
/// `envlight.release_buffers()` empties it.
mod pool {
    use std::sync::Mutex;

    /// Outputs smaller than this many floats (256 KiB) come from the allocator.
    pub const POOLED_MIN: usize = 1 << 16;
    /// The most buffers kept.
    pub const POOL_BUFFERS: usize = 8;
    /// The most bytes kept.
    pub const POOL_BYTES: usize = 512 << 20;

    static POOL: Mutex<Vec<Vec<f32>>> = Mutex::new(Vec::new());

    /// A buffer of `n` floats whose values are unspecified (the caller writes
    /// them all): a kept one of at least `n` and at most `2 n` floats when there
    /// is one, else a new one.
    pub fn take(n: usize) -> Vec<f32> {
        if n >= POOLED_MIN {
            let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
            let fits = pool
                .iter()
                .enumerate()
                .filter(|(_, b)| b.len() >= n && b.len() <= 2 * n)
                .min_by_key(|(_, b)| b.len())
                .map(|(k, _)| k);
            if let Some(k) = fits {
                let mut buffer = pool.swap_remove(k);
                buffer.truncate(n);
                return buffer;
            }
        }
        vec![0.0; n]
    }

    /// Keeps `buffer` for a later [`take`], if the pool has room.
    pub fn give(mut buffer: Vec<f32>) {
        if buffer.len() < POOLED_MIN {
            return;
        }
        // A truncated buffer's tail is initialised: give its whole length back.
        // SAFETY: every float of the capacity was written when the buffer was
        // made (`vec![0.0; n]` or a longer kept buffer), and f32 has no invalid
        // bit patterns.
        unsafe { buffer.set_len(buffer.capacity()) };
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        let bytes: usize = pool.iter().map(|b| 4 * b.len()).sum();
        if pool.len() < POOL_BUFFERS && bytes + 4 * buffer.len() <= POOL_BYTES {
            pool.push(buffer);
        }
    }

    /// Frees every kept buffer; returns how many bytes that released.
    pub fn release() -> usize {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        let bytes = pool.iter().map(|b| 4 * b.len()).sum();
        pool.clear();
        bytes
    }
}

/// The owner of a pooled output buffer behind a numpy array: returns the buffer
/// to the pool when numpy lets go of it.
#[pyclass(module = "envlight._native")]
struct PooledBuffer {
    values: numpy::ndarray::Array1<f32>,
}

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        let values = std::mem::take(&mut self.values);
        let (buffer, _) = values.into_raw_vec_and_offset();
        pool::give(buffer);
    }
}

/// An `(N,)` float32 array over `values`, owned by a [`PooledBuffer`] when the
/// buffer is big enough to be worth keeping.
fn pooled1<'py>(py: Python<'py>, values: Vec<f32>) -> PyResult<Bound<'py, PyArray1<f32>>> {
    if values.len() < pool::POOLED_MIN {
        return Ok(PyArray1::from_vec(py, values));
    }
    let owner = Bound::new(
        py,
        PooledBuffer {
            values: numpy::ndarray::Array1::from_vec(values),
        },
    )?;
    let view = owner.borrow();
    // SAFETY: the array's memory is `owner`'s, which is never reallocated or
    // changed until it is dropped, and the new array keeps `owner` alive.
    Ok(unsafe { PyArray1::borrow_from_array(&view.values, owner.clone().into_any()) })
}

/// An `(N, K)` float32 array over `values` (`N·K` floats), as [`pooled1`].
fn pooled2<'py>(
    py: Python<'py>,
    values: Vec<f32>,
    k: usize,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let n = values.len() / k;
    pooled1(py, values)?.reshape([n, k])
}

/// Frees the output buffers kept for reuse by the batch calls (see the pool);
/// returns the number of bytes released.
#[pyfunction]
fn release_buffers() -> usize {
    pool::release()
}

/// `(directions (N, 3), pdf (N,), radiance (N, 3))`.
type Samples<'py> = (
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray2<f32>>,
);

/// An importance-sampled environment light (see the `envlight` package's docs).
#[pyclass(frozen, module = "envlight._native", name = "EnvironmentLight")]
struct PyEnvironmentLight {
    light: Arc<envlight::EnvironmentLight>,
    frame: Frame,
    product: OnceLock<Arc<ProductSampler>>,
    /// The sun and the residual, found on first use (`sun`, `sun_residual`).
    sun: OnceLock<envlight::SunExtraction>,
    /// The portal light of the last portals given to `sample_portal`/`pdf_portal`
    /// (their corners, z-up), reused while the same portals come back.
    portals: std::sync::Mutex<Option<(Vec<f32>, Arc<PortalLight>)>>,
}

impl PyEnvironmentLight {
    fn build(image: EnvImage, options: LightOptions, frame: Frame) -> PyResult<Self> {
        let light = envlight::EnvironmentLight::new(image, options).map_err(to_py_err)?;
        Ok(Self {
            light: Arc::new(light),
            frame,
            product: OnceLock::new(),
            sun: OnceLock::new(),
            portals: std::sync::Mutex::new(None),
        })
    }

    /// The portal light for `portals` (anything numpy reads as `(K, 4, 3)` corners,
    /// in this light's frame): built on first use, reused while the same corners
    /// come back. `ValueError` for a bad shape or a bad quad (saying why).
    fn portal_light(
        &self,
        py: Python<'_>,
        portals: &Bound<'_, PyAny>,
    ) -> PyResult<Arc<PortalLight>> {
        let kwargs = PyDict::new(py);
        kwargs.set_item("dtype", "float32")?;
        let array = py
            .import("numpy")?
            .getattr("ascontiguousarray")?
            .call((portals,), Some(&kwargs))?;
        let array: PyReadonlyArray3<'_, f32> = array.extract().map_err(|_| {
            PyValueError::new_err("portals must have shape (K, 4, 3): K quads of four corners")
        })?;
        let shape = array.shape();
        if shape[1] != 4 || shape[2] != 3 || shape[0] == 0 {
            return Err(PyValueError::new_err(format!(
                "portals must have shape (K, 4, 3) with K ≥ 1, not {shape:?}"
            )));
        }
        let values: Vec<f32> = array.as_array().iter().copied().collect();
        let corners: Vec<f32> = self::directions(&values, self.frame)
            .iter()
            .flat_map(|p| p.to_array())
            .collect();
        let mut cache = self
            .portals
            .lock()
            .map_err(|_| PyValueError::new_err("portal cache poisoned"))?;
        if let Some((key, light)) = cache.as_ref() {
            if *key == corners {
                return Ok(light.clone());
            }
        }
        let quads = corners
            .chunks_exact(12)
            .enumerate()
            .map(|(k, c)| {
                let p = |i: usize| Vec3::new(c[3 * i], c[3 * i + 1], c[3 * i + 2]);
                Portal::new([p(0), p(1), p(2), p(3)])
                    .map_err(|e| PyValueError::new_err(format!("portal {k}: {e}")))
            })
            .collect::<PyResult<Vec<Portal>>>()?;
        let light = py
            .detach(|| PortalLight::new(self.light.clone(), &quads, PortalOptions::default()))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        let light = Arc::new(light);
        *cache = Some((corners, light.clone()));
        Ok(light)
    }

    /// The light's sun extraction, computed once with the interpreter lock released.
    fn sun_extraction(&self, py: Python<'_>) -> &envlight::SunExtraction {
        py.detach(|| {
            self.sun
                .get_or_init(|| self.light.extract_sun(&envlight::SunOptions::default()))
        })
    }

    /// One factor per shading point: the clamped cosine of each normal, or with
    /// `outgoing` and `roughness` the cosine times the GGX lobe proxy; `n` rows
    /// expected (the length of `other`).
    fn factors(
        &self,
        normals: &PyReadonlyArray2<'_, f32>,
        outgoing: Option<&PyReadonlyArray2<'_, f32>>,
        roughness: Option<f32>,
        n: usize,
        other: &str,
    ) -> PyResult<Vec<Factor>> {
        let normals = rows::<3>(normals, "normals")?;
        let normals = self::directions(&normals, self.frame);
        if normals.len() != n {
            return Err(PyValueError::new_err(format!(
                "normals and {other} must have the same length, not {} and {n}",
                normals.len()
            )));
        }
        match (outgoing, roughness) {
            (None, None) => Ok(normals.iter().map(|&n| Factor::cosine(n)).collect()),
            (Some(outgoing), Some(alpha)) => {
                if !(alpha > 0.0 && alpha <= 1.0) {
                    return Err(PyValueError::new_err(format!(
                        "roughness must be in (0, 1], not {alpha}"
                    )));
                }
                let outgoing = rows::<3>(outgoing, "outgoing")?;
                let outgoing = self::directions(&outgoing, self.frame);
                if outgoing.len() != n {
                    return Err(PyValueError::new_err(format!(
                        "outgoing must have {n} rows, not {}",
                        outgoing.len()
                    )));
                }
                Ok(normals
                    .iter()
                    .zip(outgoing.iter())
                    .map(|(&n, &wo)| Factor::glossy(n, wo, alpha))
                    .collect())
            }
            _ => Err(PyValueError::new_err(
                "outgoing and roughness go together: give both or neither",
            )),
        }
    }

    fn product(&self) -> &Arc<ProductSampler> {
        self.product.get_or_init(|| {
            Arc::new(ProductSampler::new(
                self.light.clone(),
                ProductOptions::default(),
            ))
        })
    }

    /// Draws the samples `0..n` with `draw` (given a range of sample indices and
    /// an output slice for them, in the library's batch form), a piece at a time
    /// into a small buffer, and lays them out as three flat arrays (directions in
    /// this light's frame); a missing sample is a zero direction with pdf 0 and
    /// radiance 0. Runs without the interpreter lock.
    fn draw<'py>(
        &self,
        py: Python<'py>,
        n: usize,
        draw: impl Fn(std::ops::Range<usize>, &mut [Option<envlight::LightSample>]) + Sync,
    ) -> PyResult<Samples<'py>> {
        let frame = self.frame;
        let (dirs, pdf, rgb) = py.detach(|| {
            let (mut dirs, mut pdf, mut rgb) =
                (pool::take(3 * n), pool::take(n), pool::take(3 * n));
            dirs.par_chunks_mut(3 * CHUNK)
                .zip(pdf.par_chunks_mut(CHUNK))
                .zip(rgb.par_chunks_mut(3 * CHUNK))
                .enumerate()
                .for_each(|(c, ((d, p), l))| {
                    // Each chunk in pieces whose samples stay in the first-level
                    // cache until they are laid out.
                    let mut samples = [None; PIECE];
                    let pieces = d
                        .chunks_mut(3 * PIECE)
                        .zip(p.chunks_mut(PIECE))
                        .zip(l.chunks_mut(3 * PIECE));
                    for (k, ((d, p), l)) in pieces.enumerate() {
                        let start = c * CHUNK + k * PIECE;
                        let samples = &mut samples[..p.len()];
                        draw(start..start + p.len(), samples);
                        for (k, s) in samples.iter().enumerate() {
                            let (direction, pdf, radiance) = match s {
                                Some(s) => (
                                    frame.z_up_to_frame(s.direction).to_array(),
                                    s.pdf,
                                    s.radiance,
                                ),
                                None => ([0.0; 3], 0.0, [0.0; 3]),
                            };
                            d[3 * k..3 * k + 3].copy_from_slice(&direction);
                            p[k] = pdf;
                            l[3 * k..3 * k + 3].copy_from_slice(&radiance);
                        }
                    }
                });
            (dirs, pdf, rgb)
        });
        Ok((
            pooled2(py, dirs, 3)?,
            pooled1(py, pdf)?,
            pooled2(py, rgb, 3)?,
        ))
    }
}

/// Samples per parallel task when laying results out.
const CHUNK: usize = 1 << 14;

/// Samples drawn at a time within a task (20 KiB of samples).
const PIECE: usize = 512;

/// `values` (`3 N` floats) viewed mutably as `N` RGB triples.
fn as_triples_mut(values: &mut [f32]) -> &mut [[f32; 3]] {
    // SAFETY: `[f32; 3]` has the layout of three consecutive `f32`, and the
    // length is a multiple of 3 (the callers allocate `3 N`).
    unsafe {
        std::slice::from_raw_parts_mut(values.as_mut_ptr().cast::<[f32; 3]>(), values.len() / 3)
    }
}

#[pymethods]
impl PyEnvironmentLight {
    #[new]
    #[pyo3(signature = (path, *, sampler="inversion", density=None, mapping=None, input_mapping="equirectangular", lookup="bilinear", rotate=0.0, scale=1.0, frame="z-up", table_width=None, equal_area_size=None, mis_compensation=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        path: std::path::PathBuf,
        sampler: &str,
        density: Option<&str>,
        mapping: Option<&str>,
        input_mapping: &str,
        lookup: &str,
        rotate: f32,
        scale: f32,
        frame: &str,
        table_width: Option<usize>,
        equal_area_size: Option<usize>,
        mis_compensation: bool,
    ) -> PyResult<Self> {
        let options = LightKeywords {
            sampler,
            density,
            mapping,
            input_mapping,
            lookup,
            rotate,
            scale,
            table_width,
            equal_area_size,
            mis_compensation,
        }
        .options()?;
        let frame = Frame::parse(frame)?;
        let image = py
            .detach(|| load(&path, &LoadOptions::default()))
            .map_err(to_py_err)?
            .image;
        py.detach(|| Self::build(image, options, frame))
    }

    /// A light from an `(H, W, 3)` float32 array of linear RGB radiance, row 0 at
    /// the top (θ = 0), column 0 at φ = 0.
    #[staticmethod]
    #[pyo3(signature = (rgb, *, sampler="inversion", density=None, mapping=None, input_mapping="equirectangular", lookup="bilinear", rotate=0.0, scale=1.0, frame="z-up", table_width=None, equal_area_size=None, mis_compensation=false))]
    #[allow(clippy::too_many_arguments)]
    fn from_array(
        py: Python<'_>,
        rgb: &Bound<'_, PyAny>,
        sampler: &str,
        density: Option<&str>,
        mapping: Option<&str>,
        input_mapping: &str,
        lookup: &str,
        rotate: f32,
        scale: f32,
        frame: &str,
        table_width: Option<usize>,
        equal_area_size: Option<usize>,
        mis_compensation: bool,
    ) -> PyResult<Self> {
        let rgb: PyReadonlyArray3<'_, f32> = rgb.extract().map_err(|_| {
            PyTypeError::new_err("rgb must be a numpy float32 array of shape (H, W, 3)")
        })?;
        let shape = rgb.shape();
        if shape[2] != 3 || shape[0] == 0 || shape[1] == 0 {
            return Err(PyValueError::new_err(format!(
                "rgb must have shape (H, W, 3) with H, W > 0, not {shape:?}"
            )));
        }
        let (h, w) = (shape[0], shape[1]);
        let options = LightKeywords {
            sampler,
            density,
            mapping,
            input_mapping,
            lookup,
            rotate,
            scale,
            table_width,
            equal_area_size,
            mis_compensation,
        }
        .options()?;
        let frame = Frame::parse(frame)?;
        // One copy into the image's texels (and one check of them, in
        // `EnvImage::new`), without the interpreter lock when the array is
        // C-contiguous.
        let texels: Vec<[f32; 3]> = match rgb.as_slice() {
            Ok(s) if rgb.is_c_contiguous() => py.detach(|| as_arrays::<3>(s).to_vec()),
            _ => {
                let values: Vec<f32> = rgb.as_array().iter().copied().collect();
                as_arrays::<3>(&values).to_vec()
            }
        };
        let image = py
            .detach(|| EnvImage::new(w, h, texels))
            .map_err(|e| match e {
                envlight::Error::NonFiniteTexel {
                    pos,
                    channel,
                    value,
                    ..
                } => PyValueError::new_err(format!(
                    "rgb: texel ({}, {}) is not finite: {channel} = {value}",
                    pos.x, pos.y
                )),
                e => to_py_err(e),
            })?;
        py.detach(|| Self::build(image, options, frame))
    }

    /// `(directions (N, 3), pdf (N,), radiance (N, 3))` for `u` of shape `(N, 2)`.
    fn sample<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Samples<'py>> {
        let u = rows::<2>(&u, "u")?;
        let xi = as_arrays::<2>(&u);
        self.draw(py, xi.len(), |range, out| {
            self.light.sample_batch(&xi[range], out)
        })
    }

    /// The solid-angle pdf (per steradian) of each direction of an `(N, 3)` array.
    fn pdf<'py>(
        &self,
        py: Python<'py>,
        directions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let values = rows::<3>(&directions, "directions")?;
        let dirs = self::directions(&values, self.frame);
        let mut out = pool::take(dirs.len());
        py.detach(|| self.light.pdf_batch(&dirs, &mut out));
        pooled1(py, out)
    }

    /// The radiance arriving from each direction of an `(N, 3)` array, `(N, 3)`.
    fn radiance<'py>(
        &self,
        py: Python<'py>,
        directions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let values = rows::<3>(&directions, "directions")?;
        let dirs = self::directions(&values, self.frame);
        let mut out = pool::take(3 * dirs.len());
        py.detach(|| self.light.radiance_batch(&dirs, as_triples_mut(&mut out)));
        pooled2(py, out, 3)
    }

    /// The `u` that `sample` maps to each direction, `(N, 2)`; `ValueError` for
    /// the alias sampler, which has no inverse.
    fn invert<'py>(
        &self,
        py: Python<'py>,
        directions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        if self.light.options().sampler == Sampler::Alias {
            return Err(PyValueError::new_err("the alias sampler has no inverse"));
        }
        let values = rows::<3>(&directions, "directions")?;
        let dirs = self::directions(&values, self.frame);
        let out: Vec<f32> = py.detach(|| {
            dirs.iter()
                .flat_map(|&d| self.light.invert(d).unwrap_or([0.0; 2]))
                .collect()
        });
        pooled2(py, out, 2)
    }

    /// Product sampling at shading points: `(directions, pdf, radiance)` for
    /// `normals` `(N, 3)` and `u` `(N, 2)`, drawn in proportion to radiance ×
    /// max(0, n·ω), or with `outgoing` `(N, 3)` and `roughness` also times a GGX
    /// lobe proxy about the mirror direction. A zero or non-finite normal gives
    /// pdf 0.
    #[pyo3(signature = (normals, u, *, outgoing=None, roughness=None))]
    fn sample_product<'py>(
        &self,
        py: Python<'py>,
        normals: PyReadonlyArray2<'py, f32>,
        u: PyReadonlyArray2<'py, f32>,
        outgoing: Option<PyReadonlyArray2<'py, f32>>,
        roughness: Option<f32>,
    ) -> PyResult<Samples<'py>> {
        let u = rows::<2>(&u, "u")?;
        let xi = as_arrays::<2>(&u);
        let factors = self.factors(&normals, outgoing.as_ref(), roughness, xi.len(), "u")?;
        let product = self.product();
        self.draw(py, xi.len(), |range, out| {
            product.sample_batch(&factors[range.clone()], &xi[range], out)
        })
    }

    /// The product sampler's pdf of `directions` `(N, 3)` at `normals` `(N, 3)`
    /// (and `outgoing`, `roughness`, as in `sample_product`).
    #[pyo3(signature = (normals, directions, *, outgoing=None, roughness=None))]
    fn pdf_product<'py>(
        &self,
        py: Python<'py>,
        normals: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        outgoing: Option<PyReadonlyArray2<'py, f32>>,
        roughness: Option<f32>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let values = rows::<3>(&directions, "directions")?;
        let dirs = self::directions(&values, self.frame);
        let factors = self.factors(
            &normals,
            outgoing.as_ref(),
            roughness,
            dirs.len(),
            "directions",
        )?;
        let mut out = pool::take(dirs.len());
        py.detach(|| self.product().pdf_batch(&factors, &dirs, &mut out));
        pooled1(py, out)
    }

    /// Portal sampling: one direction per point of `points` `(N, 3)` (with `u`
    /// `(N, 2)`), through the `portals` `(K, 4, 3)` only (planar convex quads, corners
    /// in order), in proportion to radiance; `(directions, pdf, radiance)`, a zero
    /// direction with pdf 0 where nothing lit is seen through a portal.
    fn sample_portal<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        u: PyReadonlyArray2<'py, f32>,
        portals: &Bound<'py, PyAny>,
    ) -> PyResult<Samples<'py>> {
        let u = rows::<2>(&u, "u")?;
        let xi = as_arrays::<2>(&u);
        let values = rows::<3>(&points, "points")?;
        let points = self::directions(&values, self.frame);
        same_length("points", points.len(), "u", xi.len())?;
        let light = self.portal_light(py, portals)?;
        self.draw(py, xi.len(), |range, out| {
            light.sample_batch(&points[range.clone()], &xi[range], out)
        })
    }

    /// The portal light's pdf (per steradian) of `directions` `(N, 3)` from
    /// `points` `(N, 3)` through `portals` `(K, 4, 3)`: 0 through no portal.
    fn pdf_portal<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        portals: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let values = rows::<3>(&directions, "directions")?;
        let dirs = self::directions(&values, self.frame);
        let values = rows::<3>(&points, "points")?;
        let points = self::directions(&values, self.frame);
        if points.len() != dirs.len() {
            return Err(PyValueError::new_err(format!(
                "points and directions must have the same length, not {} and {}",
                points.len(),
                dirs.len()
            )));
        }
        let light = self.portal_light(py, portals)?;
        let mut out = pool::take(dirs.len());
        py.detach(|| light.pdf_batch(&points, &dirs, &mut out));
        pooled1(py, out)
    }

    /// The invariant checks of docs/design.md §5 on this light (or, with `normal`, on
    /// its product sampler at that normal), as `envlight verify` runs them: a
    /// list of dicts with keys `check`, `value`, `threshold`, `samples`, `result`
    /// (`pass`, `FAIL`, `info` or `skip`).
    #[pyo3(signature = (*, samples=200_000, seed=0, normal=None))]
    fn verify<'py>(
        &self,
        py: Python<'py>,
        samples: usize,
        seed: u64,
        normal: Option<[f32; 3]>,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        if samples < 100 {
            return Err(PyValueError::new_err("samples must be at least 100"));
        }
        let config = Config {
            pdf_tolerance: 1e-3,
            lobes: Lobes::Zenith,
            reference: Reference::Midpoint,
            ..Config::with_samples(samples, seed)
        };
        let normal = match normal {
            Some(n) => Some(
                self.frame
                    .frame_to_z_up(Vec3::new(n[0], n[1], n[2]))
                    .normalized()
                    .ok_or_else(|| PyValueError::new_err("normal must be finite and non-zero"))?,
            ),
            None => None,
        };
        let rows = py.detach(|| {
            if self.light.is_black() {
                return envlight_verify::CHECKS
                    .iter()
                    .map(|c| {
                        envlight_verify::Row::new(
                            *c,
                            "map is all black",
                            "-",
                            0,
                            envlight_verify::Verdict::Skip,
                        )
                    })
                    .collect::<Vec<_>>();
            }
            match normal {
                Some(n) => {
                    let at = AtShadingPoint::new(self.product(), Factor::cosine(n));
                    let report = envlight_verify::run(&at, &at.integrand(), &config, &|_| {});
                    report.rows("product")
                }
                None => {
                    let sampler: &dyn SphereSampler = self.light.as_ref();
                    let report =
                        envlight_verify::run(sampler, &Integrand::luminance(), &config, &|_| {});
                    report.rows(self.light.options().sampler.name())
                }
            }
        });
        rows.into_iter()
            .map(|r| {
                let d = PyDict::new(py);
                d.set_item("check", r.check)?;
                d.set_item("value", r.value)?;
                d.set_item("threshold", r.threshold)?;
                d.set_item("samples", r.samples)?;
                d.set_item("result", r.verdict.label())?;
                Ok(d)
            })
            .collect()
    }

    /// The light's flat GPU tables (docs/gpu-tables.md, layout version 1) as a
    /// dict of numpy arrays: one entry per section present, by name, plus
    /// `"tables"` (the contiguous uint32 tables buffer a shader binds, sections
    /// 2-8 each padded to 16 bytes; `params[49]` words) and `"version"` (1).
    ///
    /// Sections: `params` uint32 (64,); `marginal_cdf` uint32 (table_height + 1,);
    /// `marginal_guide` uint32 (G,); `conditional_cdf` uint32 (table_height,
    /// table_width + 1); `conditional_guide` uint32 (table_height, 2**bits);
    /// `alias_slots` uint32 (n, 2) (threshold's float32 bits, alias cell);
    /// `alias_func` float32 (table_height, table_width); `bilinear_values`
    /// float32 (H + 2, W + 2); `radiance` float32 (H, W, 3) for `radiance="f32"`
    /// or float16 (H, W, 4), alpha 0, for `radiance="f16"` (unscaled: the scale
    /// is `params[36]`).
    ///
    /// Raises ValueError for the hierarchical sampler (not ported to the GPU),
    /// an unknown `radiance`, or `"f16"` with a texel above 65504.
    #[pyo3(signature = (radiance="f32"))]
    fn gpu_tables<'py>(&self, py: Python<'py>, radiance: &str) -> PyResult<Bound<'py, PyDict>> {
        use envlight::gpu::{param, section, GpuTableOptions};
        let format = choose::<RadianceFormat>("radiance", radiance)?;
        let tables = py
            .detach(|| self.light.gpu_tables(&GpuTableOptions { radiance: format }))
            .map_err(to_py_err)?;
        let p = tables.params();
        let (tw, th) = (
            p[param::TABLE_WIDTH] as usize,
            p[param::TABLE_HEIGHT] as usize,
        );
        let (w, h) = (
            p[param::IMAGE_WIDTH] as usize,
            p[param::IMAGE_HEIGHT] as usize,
        );
        let floats =
            |words: &[u32]| -> Vec<f32> { words.iter().map(|&x| f32::from_bits(x)).collect() };
        let out = PyDict::new(py);
        out.set_item("version", envlight::gpu::VERSION)?;
        out.set_item("tables", PyArray1::from_slice(py, tables.tables()))?;
        for s in tables.sections() {
            let words = tables.section_words(s.id).unwrap_or(&[]);
            let n = words.len();
            let array = match s.id {
                section::ALIAS_FUNC => PyArray1::from_vec(py, floats(words))
                    .reshape(vec![th, tw])?
                    .into_any(),
                section::BILINEAR_VALUES => PyArray1::from_vec(py, floats(words))
                    .reshape(vec![h + 2, w + 2])?
                    .into_any(),
                section::RADIANCE if format == RadianceFormat::F32 => {
                    PyArray1::from_vec(py, floats(words))
                        .reshape(vec![h, w, 3])?
                        .into_any()
                }
                section::RADIANCE => {
                    let halves: Vec<u16> = words
                        .iter()
                        .flat_map(|&x| [x as u16, (x >> 16) as u16])
                        .collect();
                    PyArray1::from_vec(py, halves)
                        .reshape(vec![h, w, 4])?
                        .call_method1("view", ("float16",))?
                }
                _ => {
                    let shape = match s.id {
                        section::CONDITIONAL_CDF => vec![th, tw + 1],
                        section::CONDITIONAL_GUIDE => vec![th, n / th.max(1)],
                        section::ALIAS_SLOTS => vec![n / 2, 2],
                        _ => vec![n],
                    };
                    PyArray1::from_slice(py, words).reshape(shape)?.into_any()
                }
            };
            out.set_item(s.name, array)?;
        }
        Ok(out)
    }

    /// The cosine product sampler's tables as numpy arrays (docs/gpu-tables.md,
    /// "Product tables"), for a port of `sample_product` / `pdf_product` without
    /// `outgoing` (the Dr.Jit one in `envlight.mitsuba`): a dict with `density`,
    /// `image` `[w, h]`, `cells` `[cw, ch]` (the texels, or the cells between the
    /// bilinear density's nodes, with `node_values` `(h + 2, w + 2)`, `u_nodes`
    /// and `v_nodes`), `patches` `[pw, ph]`, `grid`, `col_patch`, `row_patch`,
    /// `cell_widths` `(ch, cw)`, `cell_slots` `(cw ch, 2)`, `spans` `(pw ph, 5)`,
    /// `table_slots` `(nodes pw ph, 2)`, `table_widths` `(pw ph, nodes)`,
    /// `node_empty`, `node_totals`, `bright` `(B, 20)` float64, `bright_of_patch`,
    /// `bound_share`, `box_slack`, `horizon_band`, `min_horizon_band`. Directions in these tables are in the light's
    /// z-up frame before its rotation.
    fn product_tables<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = py.detach(|| self.product().cosine_tables());
        let [w, h] = t.cells.map(|x| x as usize);
        let patches = t.spans.len();
        let nodes = t.node_totals.len();
        let flat2 = |v: &[[u32; 2]]| -> Vec<u32> { v.iter().flatten().copied().collect() };
        let out = PyDict::new(py);
        out.set_item("density", t.density.name())?;
        out.set_item("image", (t.image[0], t.image[1]))?;
        out.set_item("cells", (t.cells[0], t.cells[1]))?;
        if !t.node_values.is_empty() {
            let [iw, ih] = t.image.map(|x| x as usize);
            out.set_item(
                "node_values",
                PyArray1::from_slice(py, &t.node_values).reshape(vec![ih + 2, iw + 2])?,
            )?;
            out.set_item("u_nodes", PyArray1::from_slice(py, &t.u_nodes))?;
            out.set_item("v_nodes", PyArray1::from_slice(py, &t.v_nodes))?;
        }
        out.set_item("patches", (t.patches[0], t.patches[1]))?;
        out.set_item("grid", t.grid)?;
        out.set_item("col_patch", PyArray1::from_slice(py, &t.col_patch))?;
        out.set_item("row_patch", PyArray1::from_slice(py, &t.row_patch))?;
        out.set_item(
            "cell_widths",
            PyArray1::from_slice(py, &t.cell_widths).reshape(vec![h, w])?,
        )?;
        out.set_item(
            "cell_slots",
            PyArray1::from_vec(py, flat2(&t.cell_slots)).reshape(vec![w * h, 2])?,
        )?;
        let spans: Vec<u32> = t.spans.iter().flatten().copied().collect();
        out.set_item(
            "spans",
            PyArray1::from_vec(py, spans).reshape(vec![patches, 5])?,
        )?;
        out.set_item(
            "table_slots",
            PyArray1::from_vec(py, flat2(&t.table_slots)).reshape(vec![nodes * patches, 2])?,
        )?;
        out.set_item(
            "table_widths",
            PyArray1::from_slice(py, &t.table_widths).reshape(vec![patches, nodes])?,
        )?;
        let empty: Vec<u8> = t.node_empty.iter().map(|&e| e as u8).collect();
        out.set_item("node_empty", PyArray1::from_vec(py, empty))?;
        out.set_item("node_totals", PyArray1::from_slice(py, &t.node_totals))?;
        let bright: Vec<f64> = t
            .bright
            .iter()
            .flat_map(|b| {
                let (axis, cos_half, sin_half) = b.cone;
                let mut row = vec![b.patch as f64, b.power];
                row.extend(b.centre);
                row.extend(axis);
                row.extend([cos_half, sin_half]);
                match b.latlong {
                    Some(l) => {
                        row.push(1.0);
                        row.extend(l.edge0);
                        row.extend(l.edge1);
                        row.push(if l.narrow { 1.0 } else { 0.0 });
                        row.extend(l.top);
                        row.extend(l.bottom);
                    }
                    None => row.extend([0.0; 10]),
                }
                row
            })
            .collect();
        out.set_item(
            "bright",
            PyArray1::from_vec(py, bright).reshape(vec![t.bright.len(), 20])?,
        )?;
        out.set_item(
            "bright_of_patch",
            PyArray1::from_slice(py, &t.bright_of_patch),
        )?;
        out.set_item("bound_share", t.bound_share)?;
        out.set_item("box_slack", t.box_slack)?;
        out.set_item("horizon_band", t.horizon_band)?;
        out.set_item("min_horizon_band", t.min_horizon_band)?;
        Ok(out)
    }

    /// The map's sun (its brightest compact source, as a uniform disc), or `None`
    /// when it has none (the thresholds are in the Rust docs of `envlight::sun`:
    /// radius ≤ 5°, contrast ≥ 20, ≥ 1% of the power).
    ///
    /// A dict: `direction` (unit, in this light's frame, rotation applied),
    /// `angular_radius_deg`, `solid_angle_sr`, `radiance` and `irradiance` (RGB,
    /// scale applied; irradiance at normal incidence, `L π sin² r`),
    /// `power_fraction` (share of `∫Y dω`), `elevation_deg` and `azimuth_deg` (of
    /// the z-up direction), `contrast` (disc over the surrounding sky).
    fn sun<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(sun) = self.sun_extraction(py).sun else {
            return Ok(None);
        };
        let d = self.frame.z_up_to_frame(sun.direction);
        let out = PyDict::new(py);
        out.set_item("direction", (d.x, d.y, d.z))?;
        out.set_item("angular_radius_deg", sun.angular_radius_deg())?;
        out.set_item("solid_angle_sr", sun.solid_angle)?;
        let [r, g, b] = sun.radiance;
        out.set_item("radiance", (r, g, b))?;
        let [r, g, b] = sun.irradiance;
        out.set_item("irradiance", (r, g, b))?;
        out.set_item("power_fraction", sun.power_fraction)?;
        out.set_item("elevation_deg", sun.elevation_deg())?;
        out.set_item("azimuth_deg", sun.azimuth_deg())?;
        out.set_item("contrast", sun.contrast)?;
        Ok(Some(out))
    }

    /// The light's image without its sun, as a `(height, width, 3)` float32 array:
    /// same size and mapping, the sun's texels in-painted from the sky around it,
    /// in the image's own units (the scale not applied); the image itself when
    /// there is no sun. With the disc of `sun()` it reproduces the map's
    /// irradiance at any normal that does not graze the sun.
    fn sun_residual<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let residual = &self.sun_extraction(py).residual;
        let (w, h) = (residual.width(), residual.height());
        let flat: Vec<f32> = residual.texels().iter().flatten().copied().collect();
        PyArray1::from_vec(py, flat).reshape([h, w, 3])
    }

    /// Width of the light's image in texels.
    #[getter]
    fn width(&self) -> usize {
        self.light.image().width()
    }

    /// Height of the light's image in texels.
    #[getter]
    fn height(&self) -> usize {
        self.light.image().height()
    }

    /// `(∫R dω, ∫G dω, ∫B dω)` over the sphere (scale applied).
    #[getter]
    fn integral_rgb(&self) -> (f64, f64, f64) {
        let [r, g, b] = self.light.integral_rgb();
        (r, g, b)
    }

    /// `∫Y dω` over the sphere.
    #[getter]
    fn integral_luminance(&self) -> f64 {
        self.light.integral_luminance()
    }

    /// `(∫Y dω)² / ∫(Y²/p) dω`: 1 when the pdf is proportional to luminance.
    #[getter]
    fn efficiency(&self, py: Python<'_>) -> f64 {
        py.detach(|| self.light.efficiency())
    }

    /// The direction of the brightest texel's centre, in this light's frame.
    #[getter]
    fn brightest_direction(&self) -> (f32, f32, f32) {
        let d = self.frame.z_up_to_frame(self.light.brightest().1);
        (d.x, d.y, d.z)
    }

    /// `(width, height)` of the sampling table in cells: the light's image's,
    /// unless `table_width` reduced it.
    #[getter]
    fn table_size(&self) -> (usize, usize) {
        let [w, h] = self.light.table_size();
        (w, h)
    }

    /// The efficiency the full-resolution table would have had, for a light whose
    /// table `table_width` reduced (what the reduction costs: compare with
    /// `efficiency`); `None` otherwise.
    #[getter]
    fn full_table_efficiency(&self, py: Python<'_>) -> Option<f64> {
        py.detach(|| self.light.efficiency_with_full_table().1)
    }

    /// Bytes of sampling data.
    #[getter]
    fn sampling_bytes(&self) -> usize {
        self.light.sampling_bytes()
    }

    /// `"z-up"` or `"y-up"`.
    #[getter]
    fn frame(&self) -> &'static str {
        match self.frame {
            Frame::ZUp => "z-up",
            Frame::YUp => "y-up",
        }
    }

    fn __repr__(&self) -> String {
        let o = self.light.options();
        format!(
            "EnvironmentLight({}x{}, sampler={:?}, density={:?}, mapping={:?}, frame={:?})",
            self.width(),
            self.height(),
            o.sampler.name(),
            o.density.name(),
            o.mapping.name(),
            self.frame()
        )
    }
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEnvironmentLight>()?;
    m.add_class::<visibility::PyVisibilityCache>()?;
    m.add_function(wrap_pyfunction!(release_buffers, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The accepted names of each option, in the library's order, so that Python
    // code (the Mitsuba emitter) lists them without a copy of its own.
    let names = |names: Vec<&'static str>| PyTuple::new(m.py(), names);
    m.add("SAMPLERS", names(Sampler::names())?)?;
    m.add("DENSITIES", names(Density::names())?)?;
    m.add("MAPPINGS", names(Mapping::names())?)?;
    m.add("LOOKUPS", names(Lookup::names())?)?;
    m.add("RADIANCE_FORMATS", names(RadianceFormat::names())?)?;
    Ok(())
}
