//! envlight on a GPU: uploads the flat tables of [`envlight::gpu`] and runs the
//! light's sampling, pdf and radiance queries as wgpu compute passes, with the
//! WGSL module of [`shader`].
//!
//! The CPU light builds the tables ([`envlight::EnvironmentLight::gpu_tables`]);
//! the GPU only reads them, with the CPU's algorithms (docs/gpu-tables.md), so the
//! same `ξ` give the same directions, pdfs and radiance up to f32 rounding
//! (docs/gpu.md; BENCHMARKS.md has the measured agreement).
//!
//! ```no_run
//! use envlight::{builtin, EnvironmentLight, LightOptions};
//! use envlight_gpu::{GpuDevice, GpuLight};
//!
//! let light = EnvironmentLight::new(builtin::sky(512, 256), LightOptions::default()).unwrap();
//! let device = GpuDevice::new().expect("a GPU adapter");
//! let gpu = GpuLight::new(&device, &light).unwrap();
//! let samples = gpu.sample_seeded(7, 0, 1024).unwrap();
//! assert_eq!(samples.len(), 1024);
//! ```
//!
//! The adapter follows wgpu's environment conventions: `WGPU_BACKEND` (e.g.
//! `vulkan`, `gl`) chooses the backends (default: Vulkan, Metal, DX12), `WGPU_ADAPTER_NAME` picks an adapter
//! by a substring of its name, `WGPU_POWER_PREF` (`low`, `high`) the default one.

#![warn(missing_docs)]

pub mod agreement;
pub mod sampler;
pub mod shader;

use envlight::gpu::{GpuTableOptions, GpuTables};
use envlight::EnvironmentLight;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use wgpu::util::DeviceExt;

pub use sampler::GpuSphereSampler;

/// What can go wrong on the GPU path.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter (no driver, or none matching the environment's choice).
    #[error("no GPU adapter {0}")]
    NoAdapter(String),
    /// The adapter would not give a device.
    #[error("the GPU adapter {adapter} gave no device: {reason}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's reason.
        reason: String,
    },
    /// The light cannot be put into tables (a combination not ported).
    #[error("{0}")]
    Tables(#[from] envlight::Error),
    /// A buffer larger than the device allows.
    #[error("{what} needs {bytes} bytes, more than this GPU's limit of {limit} bytes per buffer")]
    TooLarge {
        /// Which buffer.
        what: &'static str,
        /// Its size.
        bytes: u64,
        /// The device's limit.
        limit: u64,
    },
    /// The shader did not compile or a pass failed validation.
    #[error("GPU validation failed: {0}")]
    Validation(String),
    /// Reading results back failed.
    #[error("reading results back from the GPU failed: {0}")]
    Readback(String),
}

/// The install hint of the no-adapter error.
pub const NO_ADAPTER_HINT: &str = "found: install a Vulkan driver (on Debian or Ubuntu: \
apt-get install mesa-vulkan-drivers, whose lavapipe is a Vulkan device on the CPU), or \
check WGPU_BACKEND and WGPU_ADAPTER_NAME";

/// What identifies the adapter in reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdapterReport {
    /// The adapter's name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub name: String,
    /// The backend, e.g. `vulkan`.
    pub backend: String,
    /// The device type, e.g. `cpu`, `discrete-gpu`.
    pub device_type: String,
    /// The driver and its version, as the adapter reports them.
    pub driver: String,
}

/// A wgpu device chosen by the environment's conventions (see the crate docs).
#[derive(Debug, Clone)]
pub struct GpuDevice {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    /// Validation errors wgpu reports outside an error scope, kept instead of
    /// wgpu's default panic.
    uncaptured: Arc<Mutex<Vec<String>>>,
    /// Held by a dispatch from its upload to its read-back: passes from several
    /// threads (or several lights on one device) take turns. Concurrent waits on
    /// one device were measured to stall for minutes on lavapipe.
    turn: Arc<Mutex<()>>,
}

impl GpuDevice {
    /// Opens the adapter the environment names (`WGPU_BACKEND`,
    /// `WGPU_ADAPTER_NAME`, `WGPU_POWER_PREF`), or the default one, with all the
    /// limits it supports (large maps need large storage buffers).
    pub fn new() -> Result<Self, GpuError> {
        // Vulkan, Metal, DX12 unless WGPU_BACKEND says otherwise: the GL backend
        // (WGPU_BACKEND=gl) is a last resort for compute, and probing it wakes EGL
        // platforms that print to stderr.
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends,
            ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
        });
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            // wgpu's own helper for this variable panics when nothing matches.
            Ok(name) if !name.is_empty() => {
                let wanted = name.to_lowercase();
                pollster::block_on(instance.enumerate_adapters(backends))
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&wanted))
                    .ok_or_else(|| {
                        GpuError::NoAdapter(format!(
                            "named {name:?} (WGPU_ADAPTER_NAME) {NO_ADAPTER_HINT}"
                        ))
                    })?
            }
            _ => pollster::block_on(
                instance.request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                }),
            )
            .map_err(|_| {
                GpuError::NoAdapter(format!(
                    "(backends: {}) {NO_ADAPTER_HINT}",
                    backend_names(backends)
                ))
            })?,
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::NoAdapter(format!(
                "with compute shaders (the adapter {} has none) {NO_ADAPTER_HINT}",
                info.name
            )));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("envlight"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: info.name.clone(),
            reason: e.to_string(),
        })?;
        let uncaptured = Arc::new(Mutex::new(Vec::new()));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Ok(Self {
            device,
            queue,
            info,
            limits,
            uncaptured,
            turn: Arc::new(Mutex::new(())),
        })
    }

    /// The adapter's name, backend, type and driver.
    pub fn report(&self) -> AdapterReport {
        let info = &self.info;
        let device_type = match info.device_type {
            wgpu::DeviceType::Other => "other",
            wgpu::DeviceType::IntegratedGpu => "integrated-gpu",
            wgpu::DeviceType::DiscreteGpu => "discrete-gpu",
            wgpu::DeviceType::VirtualGpu => "virtual-gpu",
            wgpu::DeviceType::Cpu => "cpu",
        };
        let driver = [info.driver.as_str(), info.driver_info.as_str()]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(" ");
        AdapterReport {
            name: info.name.clone(),
            backend: info.backend.to_str().to_string(),
            device_type: device_type.to_string(),
            driver,
        }
    }

    /// The largest storage buffer a binding may hold, in bytes.
    pub fn max_storage_bytes(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// The first validation error wgpu reported outside an error scope, if any.
    fn take_uncaptured(&self) -> Option<String> {
        self.uncaptured
            .lock()
            .ok()
            .and_then(|mut v| (!v.is_empty()).then(|| v.remove(0)))
    }
}

/// One direction drawn on the GPU, as the shader writes it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuSample {
    /// World-space unit direction (the image point of `ξ` when there is no sample).
    pub direction: [f32; 3],
    /// Solid-angle pdf, per steradian, at `direction` (0: no sample).
    pub pdf: f32,
    /// Radiance along `direction`, scale applied (0 when there is no sample).
    pub radiance: [f32; 3],
    /// 1 when a direction was drawn, else 0.
    pub valid: f32,
}

impl GpuSample {
    /// True when a direction was drawn.
    pub fn is_valid(&self) -> bool {
        self.valid != 0.0
    }

    /// The row `envlight sample` writes for it.
    pub fn row(&self) -> agreement::Row {
        agreement::Row {
            direction: self.direction,
            pdf: self.pdf,
            radiance: self.radiance,
        }
    }
}

/// pdf and radiance of one direction.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuEval {
    /// Solid-angle pdf, per steradian.
    pub pdf: f32,
    /// Radiance, scale applied.
    pub radiance: [f32; 3],
}

impl GpuEval {
    /// The row `envlight eval` writes for it at `direction`.
    pub fn row(&self, direction: [f32; 3]) -> agreement::Row {
        agreement::Row {
            direction,
            pdf: self.pdf,
            radiance: self.radiance,
        }
    }
}

/// Where a batch's time went, in seconds: uploading its inputs, running the
/// kernel, and reading the results back.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Timings {
    /// Writing the inputs into device buffers (0 for seeded sampling).
    pub upload: f64,
    /// The compute pass alone, from submission to completion.
    pub kernel: f64,
    /// Copying the results to a mappable buffer and mapping them.
    pub readback: f64,
}

impl std::ops::AddAssign for Timings {
    fn add_assign(&mut self, o: Self) {
        self.upload += o.upload;
        self.kernel += o.kernel;
        self.readback += o.readback;
    }
}

/// The uniform block of one dispatch (`Batch` in the WGSL module).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Batch {
    count: u32,
    mode: u32,
    seed_lo: u32,
    seed_hi: u32,
    first_lo: u32,
    first_hi: u32,
    reserved: [u32; 2],
}

/// The four queries, one compute entry point each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Query {
    Sample,
    Pdf,
    Radiance,
    Eval,
}

impl Query {
    const ALL: [Query; 4] = [Query::Sample, Query::Pdf, Query::Radiance, Query::Eval];

    fn entry_point(self) -> &'static str {
        match self {
            Query::Sample => "sample_main",
            Query::Pdf => "pdf_main",
            Query::Radiance => "radiance_main",
            Query::Eval => "eval_main",
        }
    }

    /// f32 words each row reads.
    fn input_words(self) -> usize {
        match self {
            Query::Sample => 2,
            _ => 4,
        }
    }

    /// f32 words each row writes.
    fn output_words(self) -> usize {
        match self {
            Query::Sample => 8,
            Query::Pdf => 1,
            Query::Radiance | Query::Eval => 4,
        }
    }
}

/// Rows per workgroup (`@workgroup_size` of every entry point).
const WORKGROUP: u32 = 64;

/// A light's tables on a device, with the compute pipelines that query them.
///
/// `Send + Sync`; calls from several threads (and lights sharing a device) take
/// turns on the device.
#[derive(Debug)]
pub struct GpuLight {
    device: GpuDevice,
    params: wgpu::Buffer,
    tables: wgpu::Buffer,
    radiance: wgpu::Buffer,
    layout: wgpu::BindGroupLayout,
    pipelines: Vec<wgpu::ComputePipeline>,
    /// The parameter block as uploaded.
    words: [u32; envlight::gpu::PARAMS_WORDS],
    /// Largest number of rows in one dispatch.
    max_rows: usize,
}

impl GpuLight {
    /// Uploads `light`'s tables (f32 radiance) and builds the pipelines of
    /// [`shader::WGSL`].
    pub fn new(device: &GpuDevice, light: &EnvironmentLight) -> Result<Self, GpuError> {
        let tables = light.gpu_tables(&GpuTableOptions::default())?;
        Self::from_tables(device, &tables, shader::WGSL)
    }

    /// Uploads `tables` and builds the pipelines of the WGSL module `wgsl` (the
    /// library's [`shader::WGSL`], or a variant of it: the tests run deliberately
    /// broken ones).
    pub fn from_tables(
        device: &GpuDevice,
        tables: &GpuTables,
        wgsl: &str,
    ) -> Result<Self, GpuError> {
        let d = &device.device;
        let limit = device.max_storage_bytes();
        let fits = |what: &'static str, bytes: u64| {
            if bytes > limit {
                Err(GpuError::TooLarge { what, bytes, limit })
            } else {
                Ok(())
            }
        };
        let table_bytes: &[u8] = bytemuck::cast_slice(tables.tables());
        let radiance_bytes: &[u8] = bytemuck::cast_slice(tables.radiance());
        fits("the sampling tables", table_bytes.len() as u64)?;
        fits("the radiance image", radiance_bytes.len() as u64)?;
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let storage = |label, bytes: &[u8]| {
            // An empty binding is not allowed: pad to 16 bytes.
            let mut padded;
            let contents = if bytes.len() < 16 {
                padded = bytes.to_vec();
                padded.resize(16, 0);
                &padded[..]
            } else {
                bytes
            };
            d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let words = *tables.params();
        let params = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("envlight params"),
            contents: bytemuck::cast_slice(&words),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let tables_buffer = storage("envlight tables", table_bytes);
        let radiance = storage("envlight radiance", radiance_bytes);
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let storage_ty = |read_only| wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        let uniform_ty = wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        let layout = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("envlight"),
            entries: &[
                entry(0, uniform_ty),
                entry(1, storage_ty(true)),
                entry(2, storage_ty(true)),
                entry(3, uniform_ty),
                entry(4, storage_ty(true)),
                entry(5, storage_ty(false)),
            ],
        });
        let pipeline_layout = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("envlight"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("envlight.wgsl"),
            source: wgpu::ShaderSource::Wgsl(wgsl.into()),
        });
        let pipelines = Query::ALL
            .iter()
            .map(|q| {
                d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(q.entry_point()),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(q.entry_point()),
                    compilation_options: Default::default(),
                    cache: None,
                })
            })
            .collect();
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(e.to_string()));
        }
        // The widest row (8 words of output) bounds a dispatch's buffers.
        let max_rows = ((limit / 32) as usize).clamp(WORKGROUP as usize, 1 << 20);
        Ok(Self {
            device: device.clone(),
            params,
            tables: tables_buffer,
            radiance,
            layout,
            pipelines,
            words,
            max_rows,
        })
    }

    /// The adapter this light lives on.
    pub fn device(&self) -> &GpuDevice {
        &self.device
    }

    /// The parameter block as uploaded (docs/gpu-tables.md).
    pub fn params(&self) -> &[u32; envlight::gpu::PARAMS_WORDS] {
        &self.words
    }

    /// Bytes held on the device by the light (parameters, tables, radiance).
    pub fn device_bytes(&self) -> u64 {
        self.params.size() + self.tables.size() + self.radiance.size()
    }

    /// Samples the light at the given `ξ`.
    pub fn sample(&self, xi: &[[f32; 2]]) -> Result<Vec<GpuSample>, GpuError> {
        Ok(self.sample_timed(xi)?.0)
    }

    /// [`Self::sample`] with where the time went.
    pub fn sample_timed(&self, xi: &[[f32; 2]]) -> Result<(Vec<GpuSample>, Timings), GpuError> {
        let input: &[f32] = bytemuck::cast_slice(xi);
        self.run(Query::Sample, Some(input), xi.len(), 0, 0)
    }

    /// Samples the light at `ξ_k = envlight::rng::xi_2d(seed, k)` for
    /// `k = first..first + count`, the `ξ` drawn on the device: the rows
    /// `envlight sample --seed` writes.
    pub fn sample_seeded(
        &self,
        seed: u64,
        first: u64,
        count: usize,
    ) -> Result<Vec<GpuSample>, GpuError> {
        Ok(self.sample_seeded_timed(seed, first, count)?.0)
    }

    /// [`Self::sample_seeded`] with where the time went.
    pub fn sample_seeded_timed(
        &self,
        seed: u64,
        first: u64,
        count: usize,
    ) -> Result<(Vec<GpuSample>, Timings), GpuError> {
        self.run(Query::Sample, None, count, seed, first)
    }

    /// The solid-angle pdf of each world direction.
    pub fn pdf(&self, directions: &[[f32; 3]]) -> Result<Vec<f32>, GpuError> {
        Ok(self.pdf_timed(directions)?.0)
    }

    /// [`Self::pdf`] with where the time went.
    pub fn pdf_timed(&self, directions: &[[f32; 3]]) -> Result<(Vec<f32>, Timings), GpuError> {
        let input = padded_directions(directions);
        self.run(Query::Pdf, Some(&input), directions.len(), 0, 0)
    }

    /// The radiance along each world direction.
    pub fn radiance(&self, directions: &[[f32; 3]]) -> Result<Vec<[f32; 3]>, GpuError> {
        Ok(self.radiance_timed(directions)?.0)
    }

    /// [`Self::radiance`] with where the time went.
    pub fn radiance_timed(
        &self,
        directions: &[[f32; 3]],
    ) -> Result<(Vec<[f32; 3]>, Timings), GpuError> {
        let input = padded_directions(directions);
        let (rows, t): (Vec<[f32; 4]>, _) =
            self.run(Query::Radiance, Some(&input), directions.len(), 0, 0)?;
        Ok((rows.into_iter().map(|r| [r[0], r[1], r[2]]).collect(), t))
    }

    /// pdf and radiance of each world direction, in one pass.
    pub fn eval(&self, directions: &[[f32; 3]]) -> Result<Vec<GpuEval>, GpuError> {
        let input = padded_directions(directions);
        Ok(self
            .run(Query::Eval, Some(&input), directions.len(), 0, 0)?
            .0)
    }

    /// Runs `query` over `count` rows (in dispatches of at most `max_rows`),
    /// inputs from `input` (`None`: seeded sampling), and reads back `count`
    /// rows of `T`.
    fn run<T: bytemuck::Pod + Default>(
        &self,
        query: Query,
        input: Option<&[f32]>,
        count: usize,
        seed: u64,
        first: u64,
    ) -> Result<(Vec<T>, Timings), GpuError> {
        debug_assert_eq!(std::mem::size_of::<T>(), 4 * query.output_words());
        let mut out: Vec<T> = vec![T::default(); count];
        let mut timings = Timings::default();
        let _turn = self.device.turn.lock().unwrap_or_else(|e| e.into_inner());
        let mut start = 0usize;
        while start < count {
            let rows = (count - start).min(self.max_rows);
            let chunk_input = input.map(|i| {
                let w = query.input_words();
                &i[start * w..(start + rows) * w]
            });
            let batch = Batch {
                count: rows as u32,
                mode: u32::from(input.is_none()),
                seed_lo: seed as u32,
                seed_hi: (seed >> 32) as u32,
                first_lo: first.wrapping_add(start as u64) as u32,
                first_hi: (first.wrapping_add(start as u64) >> 32) as u32,
                reserved: [0; 2],
            };
            let t = self.dispatch(
                query,
                &batch,
                chunk_input,
                bytemuck::cast_slice_mut(&mut out[start..start + rows]),
            )?;
            timings += t;
            start += rows;
        }
        Ok((out, timings))
    }

    /// One dispatch of `batch.count` rows into `out`.
    fn dispatch(
        &self,
        query: Query,
        batch: &Batch,
        input: Option<&[f32]>,
        out: &mut [u8],
    ) -> Result<Timings, GpuError> {
        let d = &self.device.device;
        let queue = &self.device.queue;
        let rows = batch.count as usize;
        if rows == 0 {
            return Ok(Timings::default());
        }
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let upload_start = Instant::now();
        let batch_buffer = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("envlight batch"),
            contents: bytemuck::bytes_of(batch),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let input_bytes = input.map_or(16, |i| (std::mem::size_of_val(i) as u64).max(16));
        let input_buffer = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("envlight input"),
            size: input_bytes.next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        if let Some(i) = input {
            queue.write_buffer(&input_buffer, 0, bytemuck::cast_slice(i));
        }
        let output_bytes = (rows * query.output_words() * 4) as u64;
        let output = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("envlight output"),
            size: output_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("envlight read-back"),
            size: output_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.submit([]);
        self.wait()?;
        let upload = upload_start.elapsed();

        let bind_group = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("envlight"),
            layout: &self.layout,
            entries: &[
                binding(0, &self.params),
                binding(1, &self.tables),
                binding(2, &self.radiance),
                binding(3, &batch_buffer),
                binding(4, &input_buffer),
                binding(5, &output),
            ],
        });
        let kernel_start = Instant::now();
        let mut encoder = d.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipelines[query as usize]);
            pass.set_bind_group(0, &bind_group, &[]);
            let groups = (rows as u32).div_ceil(WORKGROUP);
            let x = groups.min(65_535);
            pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
        }
        queue.submit([encoder.finish()]);
        self.wait()?;
        let kernel = kernel_start.elapsed();

        let readback_start = Instant::now();
        let mut encoder = d.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&output, 0, &staging, 0, output_bytes);
        queue.submit([encoder.finish()]);
        let (sender, receiver) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = sender.send(r);
        });
        self.wait()?;
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(e.to_string()));
        }
        if let Some(e) = self.device.take_uncaptured() {
            return Err(GpuError::Validation(e));
        }
        match receiver.recv_timeout(Duration::from_secs(600)) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(GpuError::Readback(e.to_string())),
            Err(e) => return Err(GpuError::Readback(e.to_string())),
        }
        {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            out.copy_from_slice(&view);
        }
        staging.unmap();
        let readback = readback_start.elapsed();
        Ok(Timings {
            upload: upload.as_secs_f64(),
            kernel: kernel.as_secs_f64(),
            readback: readback.as_secs_f64(),
        })
    }

    /// Blocks until the device has finished everything submitted.
    fn wait(&self) -> Result<(), GpuError> {
        self.device
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }
}

/// The backends of a set, by name: `vulkan, metal, dx12`.
fn backend_names(backends: wgpu::Backends) -> String {
    [
        (wgpu::Backends::VULKAN, "vulkan"),
        (wgpu::Backends::METAL, "metal"),
        (wgpu::Backends::DX12, "dx12"),
        (wgpu::Backends::GL, "gl"),
        (wgpu::Backends::BROWSER_WEBGPU, "webgpu"),
    ]
    .into_iter()
    .filter(|(b, _)| backends.contains(*b))
    .map(|(_, name)| name)
    .collect::<Vec<_>>()
    .join(", ")
}

fn binding(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// Directions as the shader reads them: 4 floats per row.
fn padded_directions(directions: &[[f32; 3]]) -> Vec<f32> {
    directions
        .iter()
        .flat_map(|d| [d[0], d[1], d[2], 0.0])
        .collect()
}

/// The GPU guide (`docs/gpu.md`; `docs` here is a link to the repository's), whose
/// Rust blocks are doctests of this crate.
#[doc = include_str!("../docs/gpu.md")]
#[cfg(doctest)]
pub struct GpuGuide;
