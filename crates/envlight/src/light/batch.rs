//! The batch queries of an [`EnvironmentLight`] (`sample_batch`, `pdf_batch`,
//! `radiance_batch`): parallel chunks, each worked through in blocks whose
//! angles, cells and lookups are computed side by side in vector lanes, with
//! kernels compiled for AVX2 where the CPU has it. Bit for bit the single queries.

use super::{clear_of_cell_edges, solid_angle, EnvironmentLight, LightSample, Mapping, Planar};
use crate::bilinear::{BilinearDistribution2D, CentredTables};
use crate::distribution::{cell_indices, Distribution2D, Sample2D, STAGED_BLOCK};
use crate::mapping::equal_area::{self, EQUAL_AREA_JACOBIAN};
use crate::mapping::{directions_to_equirect_and_csc, radius_and_csc, EQUIRECT_JACOBIAN};
use crate::math::{is_positive_finite, prefetch_ptr, Vec3};
use crate::width::VectorWidth;
use rayon::prelude::*;

impl EnvironmentLight {
    /// [`Self::sample`] for every `ξ` in `xi`, written to `out` in order, in parallel.
    /// Each result depends only on its own `ξ`, so the output is the same for any
    /// thread count.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<LightSample>]) {
        // The bilinear density's samples end in vectorized pdfs, which wider vectors
        // speed up; the others' are scalar code, which measured 5-15% slower when
        // compiled for them (BENCHMARKS.md, session 8).
        let wide = matches!(self.planar, Planar::Bilinear(_) | Planar::Inversion(_))
            .then(Self::sample_chunk_wide);
        self.run_batch(xi, out, Self::sample_chunk, wide);
    }

    /// [`Self::sample_batch`] on one chunk, on the current thread.
    #[inline(always)]
    fn sample_chunk(&self, xi: &[[f32; 2]], out: &mut [Option<LightSample>]) {
        let one_by_one =
            |sample: &dyn Fn([f32; 2]) -> Sample2D, xi: &[[f32; 2]], out: &mut [Sample2D]| {
                for (o, &x) in out.iter_mut().zip(xi) {
                    *o = sample(x);
                }
            };
        match &self.planar {
            Planar::Inversion(d) => self.sample_blocks(
                xi,
                out,
                NO_PDFS,
                #[inline(always)]
                |xi, out| inversion_block(d, xi, out, |uv| self.image.prefetch(uv[0], uv[1])),
            ),
            Planar::Alias(d) => self.sample_blocks(
                xi,
                out,
                NO_PDFS,
                #[inline(always)]
                |xi, out| {
                    one_by_one(
                        &|x| d.sample_continuous_hinted(x, |uv| self.image.prefetch(uv[0], uv[1])),
                        xi,
                        out,
                    )
                },
            ),
            Planar::Hierarchical(d) => self.sample_blocks(
                xi,
                out,
                NO_PDFS,
                #[inline(always)]
                |xi, out| one_by_one(&|x| d.sample_continuous(x), xi, out),
            ),
            Planar::Bilinear(d) => self.sample_bilinear_blocks(
                d,
                xi,
                out,
                #[inline(always)]
                |dirs: &[Vec3], out: &mut [f32]| self.bilinear_pdfs::<false>(d, dirs, out),
            ),
        }
    }

    /// [`Self::sample_blocks`] for the bilinear density `d`, with `pdfs` giving
    /// [`Self::pdf`] at the returned directions (bit for bit).
    #[inline(always)]
    pub(super) fn sample_bilinear_blocks(
        &self,
        d: &BilinearDistribution2D,
        xi: &[[f32; 2]],
        out: &mut [Option<LightSample>],
        pdfs: impl Fn(&[Vec3], &mut [f32]),
    ) {
        self.sample_blocks(
            xi,
            out,
            Some(pdfs),
            #[inline(always)]
            |xi, out| d.sample_point_block(xi, out, |uv| self.image.prefetch(uv[0], uv[1])),
        )
    }

    /// [`Self::sample_batch`] in two stages per block of samples: all the planar
    /// samples (`planar_block`, which may overlap their memory accesses, see
    /// [`Distribution2D::sample_block`](crate::distribution::Distribution2D::sample_block)),
    /// then all the directions, pdfs and radiance lookups (the pdfs of a
    /// `continuous` density at the returned directions). A single sample is one
    /// long chain of dependent steps (CDF search, placement, sin/cos, texel loads)
    /// that the CPU cannot overlap with the next; a stage runs a block of
    /// independent short chains, which it can.
    #[inline(always)]
    fn sample_blocks(
        &self,
        xi: &[[f32; 2]],
        out: &mut [Option<LightSample>],
        continuous: Option<impl Fn(&[Vec3], &mut [f32])>,
        planar_block: impl Fn(&[[f32; 2]], &mut [Sample2D]) + Sync,
    ) {
        let mut planar = [Sample2D::default(); STAGED_BLOCK];
        for (xi, out) in xi.chunks(STAGED_BLOCK).zip(out.chunks_mut(STAGED_BLOCK)) {
            let planar = &mut planar[..xi.len()];
            planar_block(xi, planar);
            if let Some(pdfs) = &continuous {
                self.finish_continuous_block(pdfs, planar, out);
            } else {
                self.finish_constant_block(planar, out);
            }
        }
    }

    /// [`Self::finish_sample`] of a block of samples of a piecewise-constant
    /// density, [`QUERY_BLOCK`] at a time in vector lanes: the directions, their
    /// reciprocal Jacobians and the radiance at the drawn points (bit for bit the
    /// single query's). The few samples next to a cell's edge, whose direction
    /// might map back into the neighbour, take the single query's path.
    #[inline(always)]
    fn finish_constant_block(&self, planar: &[Sample2D], out: &mut [Option<LightSample>]) {
        for (planar, out) in planar.chunks(QUERY_BLOCK).zip(out.chunks_mut(QUERY_BLOCK)) {
            let (mut u, mut v) = ([0.5f32; QUERY_BLOCK], [0.5f32; QUERY_BLOCK]);
            for (j, p) in planar.iter().enumerate() {
                (u[j], v[j]) = (p.uv[0], p.uv[1]);
            }
            let ([x, y, z], _) = self.directions_lanes(&u, &v);
            let inv_jacobian = self.inv_jacobians_lanes(&x, &y, &z);
            let (mode, wrap) = (self.options.lookup, self.options.mapping.wrap());
            let lookups = self.image.lookup_block(&u, &v, mode, wrap);
            let scale = self.options.scale;
            // Which points are clear of their cells' edges, in lanes (four
            // divisions each, which one at a time cost a fifth of a sample).
            let clear = self.clear_of_edges_lanes(planar);
            for (j, (o, &p)) in out.iter_mut().zip(planar).enumerate() {
                let direction = Vec3::new(x[j], y[j], z[j]);
                *o = if p.pdf == 0.0 {
                    None
                } else if clear[j] {
                    let pdf = solid_angle(p.pdf, inv_jacobian[j]);
                    is_positive_finite(pdf).then(|| {
                        let l = self.image.fetch(&lookups, j);
                        LightSample {
                            direction,
                            pdf,
                            radiance: super::scaled(l, scale),
                            uv: p.uv,
                        }
                    })
                } else {
                    let (back, inv_jacobian) = self.options.mapping.to_uv(self.to_light(direction));
                    self.finish_constant(p, direction, back, inv_jacobian)
                };
            }
        }
    }

    /// [`Self::clear_of_edges`] of up to [`QUERY_BLOCK`] samples, as loops the
    /// compiler vectorizes (the same operations: bit for bit the same answers);
    /// lanes past the samples are false.
    #[inline(always)]
    fn clear_of_edges_lanes(&self, planar: &[Sample2D]) -> [bool; QUERY_BLOCK] {
        let [nu, nv] = self.table_size();
        let (mut u, mut v) = ([0.0f32; QUERY_BLOCK], [0.0f32; QUERY_BLOCK]);
        let (mut iu, mut iv) = ([0u32; QUERY_BLOCK], [0u32; QUERY_BLOCK]);
        for (j, p) in planar.iter().enumerate() {
            (u[j], v[j]) = (p.uv[0], p.uv[1]);
            (iu[j], iv[j]) = (p.cell[0] as u32, p.cell[1] as u32);
        }
        let (nu, nv) = (nu as f32, nv as f32);
        let mut clear = [false; QUERY_BLOCK];
        for j in 0..QUERY_BLOCK {
            clear[j] = j < planar.len()
                && clear_of_cell_edges(u[j], iu[j], nu)
                && clear_of_cell_edges(v[j], iv[j], nv);
        }
        clear
    }

    /// [`Self::uv_to_direction`] of `N` image points and the Jacobians there (as
    /// [`Mapping::to_direction`] gives them), in vector lanes where the mapping's
    /// arithmetic allows (the lat-long map's); bit for bit.
    #[inline(always)]
    fn directions_lanes<const N: usize>(
        &self,
        u: &[f32; N],
        v: &[f32; N],
    ) -> ([[f32; N]; 3], [f32; N]) {
        let (mut x, mut y, mut z) = ([0.0f32; N], [0.0f32; N], [1.0f32; N]);
        let mut jacobian = [EQUAL_AREA_JACOBIAN; N];
        match self.options.mapping {
            Mapping::Equirectangular => {
                for j in 0..N {
                    let (d, sin_theta) = crate::mapping::equirect_to_direction(u[j], v[j]);
                    (x[j], y[j], z[j]) = (d.x, d.y, d.z);
                    jacobian[j] = EQUIRECT_JACOBIAN * sin_theta;
                }
            }
            Mapping::EqualArea => {
                for j in 0..N {
                    let d = equal_area::square_to_sphere(u[j], v[j]);
                    (x[j], y[j], z[j]) = (d.x, d.y, d.z);
                }
            }
        }
        if self.rotated {
            let m = &self.options.rotation;
            for j in 0..N {
                let d = m.apply(Vec3::new(x[j], y[j], z[j]));
                (x[j], y[j], z[j]) = (d.x, d.y, d.z);
            }
        }
        ([x, y, z], jacobian)
    }

    /// [`Mapping::inv_jacobian`] at `N` world directions (rotated into the light's
    /// frame first, as [`Self::pdf`] does), in vector lanes; bit for bit.
    #[inline(always)]
    fn inv_jacobians_lanes<const N: usize>(
        &self,
        x: &[f32; N],
        y: &[f32; N],
        z: &[f32; N],
    ) -> [f32; N] {
        let mut out = [1.0 / EQUAL_AREA_JACOBIAN; N];
        if self.options.mapping == Mapping::Equirectangular {
            for j in 0..N {
                let d = self.to_light(Vec3::new(x[j], y[j], z[j]));
                out[j] = radius_and_csc(d).1 * (1.0 / EQUIRECT_JACOBIAN);
            }
        }
        out
    }

    /// [`Self::finish_sample`] of a block of samples of a continuous density: the
    /// directions and radiance lookups in vector lanes, [`QUERY_BLOCK`] at a time,
    /// then the pdfs at the directions as [`Self::pdf_batch`] computes them (so
    /// bit for bit [`Self::pdf`]).
    #[inline(always)]
    fn finish_continuous_block(
        &self,
        pdfs_at: &impl Fn(&[Vec3], &mut [f32]),
        planar: &[Sample2D],
        out: &mut [Option<LightSample>],
    ) {
        let n = planar.len();
        let mut directions = [Vec3::new(0.0, 0.0, 1.0); STAGED_BLOCK];
        let mut jacobians = [0.0f32; STAGED_BLOCK];
        let mut radiance = [[0.0f32; 3]; STAGED_BLOCK];
        let scale = self.options.scale;
        let (mode, wrap) = (self.options.lookup, self.options.mapping.wrap());
        for (k, planar) in planar.chunks(QUERY_BLOCK).enumerate() {
            let (mut u, mut v) = ([0.5f32; QUERY_BLOCK], [0.5f32; QUERY_BLOCK]);
            for (j, p) in planar.iter().enumerate() {
                (u[j], v[j]) = (p.uv[0], p.uv[1]);
            }
            let ([x, y, z], jacobian) = self.directions_lanes(&u, &v);
            let lookups = self.image.lookup_block(&u, &v, mode, wrap);
            for j in 0..planar.len() {
                let at = k * QUERY_BLOCK + j;
                directions[at] = Vec3::new(x[j], y[j], z[j]);
                jacobians[at] = jacobian[j];
                let l = self.image.fetch(&lookups, j);
                radiance[at] = super::scaled(l, scale);
            }
        }
        let mut pdfs = [0.0f32; STAGED_BLOCK];
        pdfs_at(&directions[..n], &mut pdfs[..n]);
        for (k, (o, p)) in out.iter_mut().zip(planar).enumerate() {
            let pdf = pdfs[k];
            *o = (p.pdf != 0.0 && jacobians[k] > 0.0 && is_positive_finite(pdf)).then(|| {
                LightSample {
                    direction: directions[k],
                    pdf,
                    radiance: radiance[k],
                    uv: p.uv,
                }
            });
        }
    }

    /// [`Self::pdf`] for every direction in `directions`, in parallel, bit for bit
    /// the single calls' values. Each thread works through blocks of directions
    /// whose angles and cells it computes side by side in vector lanes (AVX2
    /// where the CPU has it), several times cheaper per direction than single
    /// calls.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        self.run_batch(
            directions,
            out,
            Self::pdf_chunk,
            Some(Self::pdf_chunk_wide()),
        );
    }

    /// Hands matching chunks of `input` (directions or samples) and `out` to
    /// `kernel`, in parallel, or to the same code compiled for the widest vectors
    /// the CPU has ([`VectorWidth`]) from `wide`, when given.
    fn run_batch<I: Sync, O: Send>(
        &self,
        input: &[I],
        out: &mut [O],
        kernel: fn(&Self, &[I], &mut [O]),
        wide: Option<WideKernels<Self, I, O>>,
    ) {
        let width = VectorWidth::detect();
        batch_chunks(input, out, |input, out| match (width, &wide) {
            // SAFETY: each wide kernel runs only on a CPU with its features.
            (VectorWidth::Avx512, Some(wide)) => unsafe { (wide.avx512)(self, input, out) },
            (VectorWidth::Avx2, Some(wide)) => unsafe { (wide.avx2)(self, input, out) },
            _ => kernel(self, input, out),
        });
    }

    wide_kernels! {
        sample_chunk_wide => sample_chunk([f32; 2], Option<LightSample>) or super::avx512::sample_chunk;
        pdf_chunk_wide => pdf_chunk(Vec3, f32) or super::avx512::pdf_chunk;
        radiance_chunk_wide => radiance_chunk(Vec3, [f32; 3]) or super::avx512::radiance_chunk;
    }

    /// [`Self::pdf_batch`] on one chunk, on the current thread. For the
    /// piecewise-constant samplers the cells of a block are found together too
    /// ([`cell_indices`]) and fetched a block ahead; the bilinear density's
    /// patches likewise.
    #[inline(always)]
    fn pdf_chunk(&self, dirs: &[Vec3], out: &mut [f32]) {
        match &self.planar {
            Planar::Inversion(d) => self.pdf_cell_lanes(
                dirs,
                out,
                [d.nu(), d.nv()],
                |iu, iv| d.prefetch_cell(iu, iv),
                |iu, iv| d.cell_pdfs_in_grid(iu, iv),
            ),
            Planar::Alias(d) => self.pdf_cell_lanes(
                dirs,
                out,
                [d.nu(), d.nv()],
                |iu, iv| d.prefetch_cell(iu, iv),
                |iu, iv| lane_by_lane(iu, iv, |iu, iv| d.cell_pdf(iu, iv)),
            ),
            Planar::Hierarchical(d) => self.pdf_cell_lanes(
                dirs,
                out,
                [d.nu(), d.nv()],
                |_, _| {},
                |iu, iv| lane_by_lane(iu, iv, |iu, iv| d.cell_pdf(iu, iv)),
            ),
            Planar::Bilinear(d) => self.bilinear_pdfs::<true>(d, dirs, out),
        }
    }

    /// [`Self::pdf_chunk`] for the bilinear density `d`: each block's patches
    /// located (and with `PREFETCH`, their data fetched a block ahead), then their
    /// densities, in vector lanes where the nodes are the texel-centre layout (as
    /// the light builds them). Sampling, whose patches are in cache already, skips
    /// the prefetches.
    #[inline(always)]
    fn bilinear_pdfs<const PREFETCH: bool>(
        &self,
        d: &BilinearDistribution2D,
        dirs: &[Vec3],
        out: &mut [f32],
    ) {
        let Some(CentredTables {
            cells, node_rows, ..
        }) = d.centred_tables()
        else {
            return self.bilinear_pdfs_located::<PREFETCH>(d, dirs, out);
        };
        self.uv_blocks::<true, _, _>(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let (i, k) =
                    BilinearDistribution2D::centred_patches(cells, node_rows, &block.u, &block.v);
                if PREFETCH {
                    for (&i, &k) in i.iter().zip(&k) {
                        d.prefetch_patch([i as usize, k as usize]);
                    }
                }
                (*block, i, k)
            },
            #[inline(always)]
            |(block, i, k): &(UvBlock, [u32; QUERY_BLOCK], [u32; QUERY_BLOCK]), out| {
                let planar = d.pdf_in_centred_patches([i, k], &block.u, &block.v);
                let mut pdf = [0.0f32; QUERY_BLOCK];
                for j in 0..QUERY_BLOCK {
                    pdf[j] = solid_angle(planar[j], block.inv_jacobian[j]);
                }
                out.copy_from_slice(&pdf[..out.len()]);
            },
        )
    }

    /// [`Self::bilinear_pdfs`] for any node layout: each lane's patch located
    /// through the nodes' guide tables.
    #[inline(always)]
    fn bilinear_pdfs_located<const PREFETCH: bool>(
        &self,
        d: &BilinearDistribution2D,
        dirs: &[Vec3],
        out: &mut [f32],
    ) {
        self.uv_blocks::<true, _, _>(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let mut patches = PatchBlock {
                    patch: [[0; 2]; QUERY_BLOCK],
                    point: [[0.0; 2]; QUERY_BLOCK],
                    inv_jacobian: block.inv_jacobian,
                };
                for i in 0..QUERY_BLOCK {
                    let (patch, point) = d.locate([block.u[i], block.v[i]]);
                    if PREFETCH {
                        d.prefetch_patch(patch);
                    }
                    (patches.patch[i], patches.point[i]) = (patch, point);
                }
                patches
            },
            #[inline(always)]
            |patches: &PatchBlock, out| {
                let mut planar = [0.0f32; QUERY_BLOCK];
                d.pdf_in_patches(&patches.patch, &patches.point, &mut planar);
                for (i, o) in out.iter_mut().enumerate() {
                    *o = solid_angle(planar[i], patches.inv_jacobian[i]);
                }
            },
        )
    }

    /// The pdf stage of [`Self::pdf_batch`] for a piecewise-constant density over
    /// a `grid[0] × grid[1]` grid of cells: `cell_pdfs` of the block's cells at
    /// the image points of [`Self::uv_blocks`], over the Jacobians. `prefetch`
    /// asks for a cell's data a block before `cell_pdfs` reads it.
    #[inline(always)]
    fn pdf_cell_lanes(
        &self,
        dirs: &[Vec3],
        out: &mut [f32],
        [nu, nv]: [usize; 2],
        prefetch: impl Fn(usize, usize),
        cell_pdfs: impl Fn(&[u32; QUERY_BLOCK], &[u32; QUERY_BLOCK]) -> [f32; QUERY_BLOCK],
    ) {
        self.uv_blocks::<true, _, _>(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let (iu, iv) = (cell_indices(&block.u, nu), cell_indices(&block.v, nv));
                for (&iu, &iv) in iu.iter().zip(&iv) {
                    prefetch(iu as usize, iv as usize);
                }
                CellBlock {
                    iu,
                    iv,
                    inv_jacobian: block.inv_jacobian,
                }
            },
            #[inline(always)]
            |cells: &CellBlock, out| {
                let planar = cell_pdfs(&cells.iu, &cells.iv);
                let mut pdf = [0.0f32; QUERY_BLOCK];
                for i in 0..QUERY_BLOCK {
                    pdf[i] = solid_angle(planar[i], cells.inv_jacobian[i]);
                }
                out.copy_from_slice(&pdf[..out.len()]);
            },
        );
    }

    /// Cuts `dirs` into blocks of [`QUERY_BLOCK`] directions and computes each
    /// block's image points and reciprocal Jacobians together
    /// ([`Self::to_uv_block`]). `prepare` then turns them into whatever `finish`
    /// needs and starts fetching the memory it will read; `finish` writes the
    /// results into the matching part of `out`, one block later: a block's cache
    /// misses are under way while the next block's angles are computed. The last
    /// block is padded; `out` is as long as the real part. With `INPUT_PREFETCH`
    /// the input is fetched [`INPUT_AHEAD`] blocks ahead.
    #[inline(always)]
    fn uv_blocks<const INPUT_PREFETCH: bool, O, P>(
        &self,
        dirs: &[Vec3],
        out: &mut [O],
        prepare: impl Fn(&UvBlock) -> P,
        mut finish: impl FnMut(&P, &mut [O]),
    ) {
        // Coordinates in separate arrays, the layout vector instructions read. Each
        // block's arrays are written one block ahead: vector loads of data just
        // written by scalar stores wait for the stores to retire (they cannot be
        // forwarded), which cost about 5% of a batch pdf or radiance query.
        #[inline(always)]
        fn transpose(dirs: &[Vec3]) -> [[f32; QUERY_BLOCK]; 3] {
            let mut xyz = [
                [0.0f32; QUERY_BLOCK],
                [0.0; QUERY_BLOCK],
                [1.0; QUERY_BLOCK],
            ];
            if let Ok(full) = <&[Vec3; QUERY_BLOCK]>::try_from(dirs) {
                // A whole block as one array of coordinates, read with fixed
                // strides: the compiler turns this into vector loads and shuffles.
                // SAFETY: `Vec3` is `repr(C)` over three `f32`.
                let flat: &[f32; 3 * QUERY_BLOCK] = unsafe { &*(full as *const _ as *const _) };
                for i in 0..QUERY_BLOCK {
                    (xyz[0][i], xyz[1][i], xyz[2][i]) =
                        (flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]);
                }
                return xyz;
            }
            for (i, d) in dirs.iter().enumerate() {
                (xyz[0][i], xyz[1][i], xyz[2][i]) = (d.x, d.y, d.z);
            }
            xyz
        }
        // Two slots used in turn: a block's prepared data stays where `prepare`
        // wrote it until `finish` reads it, one block later, rather than being
        // moved in and out of a single pending slot (a further 3-5%).
        let mut slots: [Option<(P, &mut [O])>; 2] = [None, None];
        let mut blocks = dirs.chunks(QUERY_BLOCK).zip(out.chunks_mut(QUERY_BLOCK));
        let mut next = blocks.next().map(|(d, o)| (transpose(d), o));
        let mut k = 0;
        while let Some(([x, y, z], out)) = next.take() {
            // With `INPUT_PREFETCH`, the directions a few blocks on start loading
            // now: the stream's cache misses otherwise stall the transposition of
            // a pdf query (1.1-1.3x faster at 1k). A radiance query, whose texel
            // prefetches fill the queue of outstanding misses, measured no faster
            // with it on a 1k map and slower on 2k-4k ones.
            let ahead = (k + INPUT_AHEAD) * QUERY_BLOCK;
            let lines = if INPUT_PREFETCH {
                QUERY_BLOCK * std::mem::size_of::<Vec3>() / 64
            } else {
                0
            };
            for line in 0..lines {
                prefetch_ptr(
                    dirs.as_ptr()
                        .wrapping_add(ahead)
                        .cast::<u8>()
                        .wrapping_add(64 * line),
                );
            }
            next = blocks.next().map(|(d, o)| (transpose(d), o));
            slots[k & 1] = Some((prepare(&self.to_uv_block(x, y, z)), out));
            if let Some((previous, previous_out)) = &mut slots[(k + 1) & 1] {
                finish(previous, previous_out);
            }
            slots[(k + 1) & 1] = None;
            k += 1;
        }
        if let Some((last, last_out)) = &mut slots[(k + 1) & 1] {
            finish(last, last_out);
        }
    }

    /// [`Mapping::to_uv`] of a block of world directions (rotated into the light's
    /// frame), as loops over the block that the compiler vectorizes: a query's
    /// angles are a long chain of dependent steps (square roots, a division, a
    /// polynomial) that one query at a time leaves the CPU waiting on; a block
    /// computes many side by side, several per instruction. Bit for bit the
    /// single-direction values.
    #[inline(always)]
    fn to_uv_block(
        &self,
        mut x: [f32; QUERY_BLOCK],
        mut y: [f32; QUERY_BLOCK],
        mut z: [f32; QUERY_BLOCK],
    ) -> UvBlock {
        if self.rotated {
            for i in 0..QUERY_BLOCK {
                let d = self.world_to_light.apply(Vec3::new(x[i], y[i], z[i]));
                (x[i], y[i], z[i]) = (d.x, d.y, d.z);
            }
        }
        match self.options.mapping {
            Mapping::Equirectangular => {
                let (u, v, mut inv_jacobian) = directions_to_equirect_and_csc(&x, &y, &z);
                for j in &mut inv_jacobian {
                    *j *= 1.0 / EQUIRECT_JACOBIAN;
                }
                UvBlock { u, v, inv_jacobian }
            }
            Mapping::EqualArea => {
                let (u, v) = equal_area::spheres_to_square(&x, &y, &z);
                UvBlock {
                    u,
                    v,
                    inv_jacobian: [1.0 / EQUAL_AREA_JACOBIAN; QUERY_BLOCK],
                }
            }
        }
    }

    /// [`Self::radiance`] for every direction in `directions`, in parallel, bit for
    /// bit the single calls' values, computed in blocks like [`Self::pdf_batch`].
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        self.run_batch(
            directions,
            out,
            Self::radiance_chunk,
            Some(Self::radiance_chunk_wide()),
        );
    }

    /// [`Self::radiance_batch`] on one chunk, on the current thread.
    #[inline(always)]
    fn radiance_chunk(&self, dirs: &[Vec3], out: &mut [[f32; 3]]) {
        self.uv_blocks::<false, _, _>(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let (mode, wrap) = (self.options.lookup, self.options.mapping.wrap());
                let lookups = self.image.lookup_block(&block.u, &block.v, mode, wrap);
                self.image.prefetch_block(&lookups);
                lookups
            },
            #[inline(always)]
            |lookups: &crate::image::LookupBlock<QUERY_BLOCK>, out| {
                let s = self.options.scale;
                for (i, o) in out.iter_mut().enumerate() {
                    let l = self.image.fetch(lookups, i);
                    *o = super::scaled(l, s);
                }
            },
        )
    }
}

/// [`Distribution2D::sample_continuous_hinted`] of a block of `ξ` (at most
/// [`STAGED_BLOCK`]) in vector lanes ([`Distribution2D::staged_lanes`]), bit for
/// bit; `hint` hears each point as soon as it is placed.
#[inline(always)]
fn inversion_block(
    d: &Distribution2D,
    xi: &[[f32; 2]],
    out: &mut [Sample2D],
    hint: impl Fn([f32; 2]),
) {
    d.staged_lanes(
        xi,
        out,
        #[inline(always)]
        |rows, out| {
            let s = d.finish_lanes(rows);
            for (j, o) in out.iter_mut().enumerate() {
                hint([s.u[j], s.v[j]]);
                *o = Sample2D {
                    uv: [s.u[j], s.v[j]],
                    pdf: s.pdf[j],
                    cell: [s.iu[j] as usize, s.iv[j] as usize],
                };
            }
        },
    );
}

/// `cell_pdf` of each of `N` cells `[iu[j], iv[j]]`, one lane at a time (for
/// densities without a vector-lane lookup).
#[inline(always)]
fn lane_by_lane<const N: usize>(
    iu: &[u32; N],
    iv: &[u32; N],
    cell_pdf: impl Fn(usize, usize) -> f32,
) -> [f32; N] {
    let mut out = [0.0f32; N];
    for (o, (&iu, &iv)) in out.iter_mut().zip(iu.iter().zip(iv)) {
        *o = cell_pdf(iu as usize, iv as usize);
    }
    out
}

/// The `continuous` argument of [`EnvironmentLight::sample_blocks`] for a
/// piecewise-constant density (none).
const NO_PDFS: Option<PdfsAt> = None;

/// A function writing [`EnvironmentLight::pdf`] at each of a block's directions.
type PdfsAt = fn(&[Vec3], &mut [f32]);

/// Directions per block in the batch queries' vectorized stage
/// ([`EnvironmentLight::to_uv_block`]): enough for several vectors of the widest
/// kind, few enough that the block's arrays stay in registers and L1.
const QUERY_BLOCK: usize = 16;

/// How many blocks ahead [`EnvironmentLight::uv_blocks`] asks for the input
/// directions.
const INPUT_AHEAD: usize = 8;

/// A block of directions' image points (`u`, `v`) and reciprocal Jacobians,
/// lane by lane.
#[derive(Clone, Copy)]
struct UvBlock {
    u: [f32; QUERY_BLOCK],
    v: [f32; QUERY_BLOCK],
    inv_jacobian: [f32; QUERY_BLOCK],
}

/// A block's bilinear patches, the points in them and the reciprocal Jacobians,
/// lane by lane.
struct PatchBlock {
    patch: [[usize; 2]; QUERY_BLOCK],
    point: [[f64; 2]; QUERY_BLOCK],
    inv_jacobian: [f32; QUERY_BLOCK],
}

/// A block's grid cells (`iu`, `iv`) and reciprocal Jacobians, lane by lane.
struct CellBlock {
    iu: [u32; QUERY_BLOCK],
    iv: [u32; QUERY_BLOCK],
    inv_jacobian: [f32; QUERY_BLOCK],
}

/// A batch kernel compiled for AVX2 and for AVX-512 ([`VectorWidth`]).
struct WideKernels<L, I, O> {
    avx2: unsafe fn(&L, &[I], &mut [O]),
    avx512: unsafe fn(&L, &[I], &mut [O]),
}

/// For each `name => kernel(I, O)`, a method `name()` returning `kernel` compiled
/// for AVX2 and for AVX-512 ([`WideKernels`]). With `or special`, the AVX-512
/// kernel first offers the chunk to `special` (a hand-written kernel returning
/// whether it applied to this light).
macro_rules! wide_kernels {
    ($($name:ident => $kernel:ident($in:ty, $out:ty) $(or $special:path)?;)*) => {$(
        #[doc = concat!("[`Self::", stringify!($kernel), "`] compiled for wider vectors.")]
        fn $name() -> WideKernels<Self, $in, $out> {
            #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
            fn avx2(light: &EnvironmentLight, input: &[$in], out: &mut [$out]) {
                light.$kernel(input, out)
            }
            #[cfg_attr(
                target_arch = "x86_64",
                target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")
            )]
            fn avx512(light: &EnvironmentLight, input: &[$in], out: &mut [$out]) {
                $(
                    #[cfg(target_arch = "x86_64")]
                    if $special(light, input, out) {
                        return;
                    }
                )?
                light.$kernel(input, out)
            }
            WideKernels { avx2, avx512 }
        }
    )*};
}
use wide_kernels;

/// Hands matching chunks of `input` and `out` to `f`, in parallel.
///
/// # Panics
/// When the slices differ in length.
fn batch_chunks<I: Sync, O: Send>(input: &[I], out: &mut [O], f: impl Fn(&[I], &mut [O]) + Sync) {
    assert_eq!(
        input.len(),
        out.len(),
        "batch input and output lengths differ"
    );
    const CHUNK: usize = 4096;
    out.par_chunks_mut(CHUNK)
        .zip(input.par_chunks(CHUNK))
        .for_each(|(o, i)| f(i, o));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Lookup;
    use crate::light::{Density, LightOptions, Sampler};
    use crate::math::Rotation;

    /// The batch kernels at every vector width this CPU runs (the baseline's two
    /// f64 lanes, AVX2, AVX-512; the public calls pick only the widest): bit for
    /// bit the single queries, for every density (tests/threads.rs covers the
    /// public calls too).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn bilinear_pdfs_read_ahead_on_large_tables_equal_single_queries() {
        // Tables beyond `PREFETCH_ABOVE` take the AVX-512 pdf kernel's other
        // loop, each block finished one block later: the same values, also for
        // a last block of each length below 16.
        if !supports(VectorWidth::Avx512) {
            eprintln!("skipped: this CPU has no AVX-512");
            return;
        }
        let options = LightOptions {
            density: Density::PiecewiseBilinear,
            ..Default::default()
        };
        let light = EnvironmentLight::new(crate::builtin::sky(2048, 1024), options).unwrap();
        let Planar::Bilinear(d) = &light.planar else {
            panic!("a bilinear light");
        };
        let t = d.centred_tables().expect("the light's layout");
        let bytes = std::mem::size_of_val(t.values) + std::mem::size_of_val(t.factors);
        assert!(
            bytes > super::super::avx512::PREFETCH_ABOVE,
            "{bytes} bytes"
        );
        let mut dirs: Vec<Vec3> = (0..2_000u64)
            .map(|k| crate::math::uniform_sphere(crate::rng::xi_2d(8, k)))
            .collect();
        dirs.extend([Vec3::new(0.0, 0.0, 1.0), Vec3::new(f32::NAN, 0.0, 1.0)]);
        for n in (dirs.len() - 17)..=dirs.len() {
            let mut pdfs = vec![0.0; n];
            // SAFETY: the CPU has AVX-512 (checked above).
            unsafe { (EnvironmentLight::pdf_chunk_wide().avx512)(&light, &dirs[..n], &mut pdfs) };
            for (p, &d) in pdfs.iter().zip(&dirs) {
                assert_eq!(p.to_bits(), light.pdf(d).to_bits(), "{n} {d:?}");
            }
        }
    }

    #[test]
    fn batch_kernels_at_every_width_equal_single_queries() {
        // A coarse sky, and one whose sun covers a few texels of long rows (the
        // sampling searches among many faint cells).
        // The last has power-of-two sides (the AVX-512 bilinear pdf computes its
        // nodes then).
        let images = [
            crate::builtin::sky(96, 48),
            crate::builtin::sky(720, 360),
            crate::builtin::sky(256, 128),
        ];
        let mut dirs: Vec<Vec3> = (0..1_001u64)
            .map(|k| crate::math::uniform_sphere(crate::rng::xi_2d(5, k)))
            .collect();
        dirs.extend([
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, -1e-7, 0.0),
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::new(1e-30, 0.0, 1.0),
            Vec3::new(-1.0, -1e-20, 0.0),
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(1e30, -1e30, 1e30),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
        ]);
        let xi: Vec<[f32; 2]> = (0..1_003u64).map(|k| crate::rng::xi_2d(6, k)).collect();
        let widths: Vec<VectorWidth> = [
            VectorWidth::Baseline,
            VectorWidth::Avx2,
            VectorWidth::Avx512,
        ]
        .into_iter()
        .filter(|&w| w == VectorWidth::Baseline || supports(w))
        .collect();
        for (sampler, density, lookup, mapping) in [
            (
                Sampler::Inversion,
                Density::PiecewiseConstant,
                Lookup::Bilinear,
                Mapping::Equirectangular,
            ),
            (
                Sampler::Alias,
                Density::PiecewiseConstant,
                Lookup::Nearest,
                Mapping::Equirectangular,
            ),
            (
                Sampler::Hierarchical,
                Density::PiecewiseConstant,
                Lookup::Bilinear,
                Mapping::EqualArea,
            ),
            (
                Sampler::Inversion,
                Density::PiecewiseConstant,
                Lookup::Node,
                Mapping::Equirectangular,
            ),
            (
                Sampler::Inversion,
                Density::PiecewiseBilinear,
                Lookup::Bilinear,
                Mapping::Equirectangular,
            ),
            (
                Sampler::Inversion,
                Density::PiecewiseBilinear,
                Lookup::Nearest,
                Mapping::EqualArea,
            ),
            // Node rows along v: the AVX-512 kernels decline them (their nodes
            // are texel centres), the others locate patches through the nodes.
            (
                Sampler::Inversion,
                Density::PiecewiseBilinear,
                Lookup::Node,
                Mapping::Equirectangular,
            ),
        ] {
            // Rotated and not: the AVX-512 kernels skip the rotation for the identity.
            let cases = [0.0, 20.0].into_iter().flat_map(|degrees| {
                let widths = &widths;
                images.iter().flat_map(move |i| {
                    widths
                        .iter()
                        .map(move |w| (Rotation::about_z_degrees(degrees), i, *w))
                })
            });
            for (rotation, image, width) in cases {
                let options = LightOptions {
                    sampler,
                    density,
                    lookup,
                    mapping,
                    rotation,
                    ..Default::default()
                };
                let light = EnvironmentLight::new(image.clone(), options).unwrap();
                let case = format!(
                    "{sampler:?} {density:?} {lookup:?} {width:?} {} {rotation:?}",
                    image.width()
                );
                let (pdfs, radiance, samples) = chunks_at(width, &light, &dirs, &xi);
                for (k, &d) in dirs.iter().enumerate() {
                    assert_eq!(pdfs[k].to_bits(), light.pdf(d).to_bits(), "{case} {d:?}");
                    assert_eq!(
                        radiance[k].map(f32::to_bits),
                        light.radiance(d).map(f32::to_bits),
                        "{case} {d:?}"
                    );
                }
                for (k, &x) in xi.iter().enumerate() {
                    assert_eq!(samples[k], light.sample(x), "{case} {x:?}");
                }
            }
        }
    }

    /// Texels at f32::MAX (which a bilinear blend's weights, summing to just
    /// above 1, once carried to infinity: a fuzzer's find) and scales that
    /// overflow: radiance stays finite on every path and width (the largest
    /// finite f32 where it would overflow, 0 for scale 0), bit for bit the
    /// single queries'.
    #[test]
    fn radiance_of_the_brightest_texels_stays_finite_at_every_width() {
        let image = crate::EnvImage::from_fn(8, 4, |_, _| [f32::MAX; 3]).unwrap();
        let dirs: Vec<Vec3> = (0..997u64)
            .map(|k| crate::math::uniform_sphere(crate::rng::xi_2d(9, k)))
            .collect();
        let xi: Vec<[f32; 2]> = (0..997u64).map(|k| crate::rng::xi_2d(10, k)).collect();
        for (density, lookup, scale) in [
            (Density::PiecewiseBilinear, Lookup::Bilinear, 1.0),
            (Density::PiecewiseBilinear, Lookup::Node, 1.0),
            (Density::PiecewiseConstant, Lookup::Bilinear, 1.0),
            (Density::PiecewiseBilinear, Lookup::Bilinear, 3.0),
            (Density::PiecewiseConstant, Lookup::Nearest, 3.0),
            (Density::PiecewiseBilinear, Lookup::Bilinear, 0.0),
        ] {
            let options = LightOptions {
                density,
                lookup,
                scale,
                ..Default::default()
            };
            let light = EnvironmentLight::new(image.clone(), options).unwrap();
            let case = format!("{density:?} {lookup:?} scale {scale}");
            let expected = |l: [f32; 3]| {
                let finite = l.iter().all(|c| c.is_finite() && *c >= 0.0);
                finite && (scale > 0.0 || l == [0.0; 3])
            };
            for width in [
                VectorWidth::Baseline,
                VectorWidth::Avx2,
                VectorWidth::Avx512,
            ] {
                if !supports(width) {
                    continue;
                }
                let (_, radiance, samples) = chunks_at(width, &light, &dirs, &xi);
                for (k, &d) in dirs.iter().enumerate() {
                    let single = light.radiance(d);
                    assert!(expected(single), "{case} {d:?}: {single:?}");
                    assert_eq!(radiance[k].map(f32::to_bits), single.map(f32::to_bits));
                }
                for (k, &x) in xi.iter().enumerate() {
                    let single = light.sample(x);
                    if let Some(s) = single {
                        assert!(expected(s.radiance), "{case} {x:?}: {:?}", s.radiance);
                    }
                    assert_eq!(samples[k], single, "{case} {width:?} {x:?}");
                }
            }
        }
    }

    /// The chunk kernels' pdfs and radiance at `dirs` and samples at `xi`, as
    /// compiled for `width`.
    ///
    /// # Panics
    /// When this CPU does not run `width`'s kernels.
    fn chunks_at(
        width: VectorWidth,
        light: &EnvironmentLight,
        dirs: &[Vec3],
        xi: &[[f32; 2]],
    ) -> (Vec<f32>, Vec<[f32; 3]>, Vec<Option<LightSample>>) {
        assert!(supports(width), "{width:?} kernels on this CPU");
        let mut pdfs = vec![0.0; dirs.len()];
        let mut radiance = vec![[0.0; 3]; dirs.len()];
        let mut samples = vec![None; xi.len()];
        let (pdf, rad, sample) = match width {
            VectorWidth::Baseline => {
                light.pdf_chunk(dirs, &mut pdfs);
                light.radiance_chunk(dirs, &mut radiance);
                light.sample_chunk(xi, &mut samples);
                return (pdfs, radiance, samples);
            }
            VectorWidth::Avx2 => (
                EnvironmentLight::pdf_chunk_wide().avx2,
                EnvironmentLight::radiance_chunk_wide().avx2,
                EnvironmentLight::sample_chunk_wide().avx2,
            ),
            VectorWidth::Avx512 => (
                EnvironmentLight::pdf_chunk_wide().avx512,
                EnvironmentLight::radiance_chunk_wide().avx512,
                EnvironmentLight::sample_chunk_wide().avx512,
            ),
        };
        // SAFETY: this CPU runs `width`'s kernels (asserted above).
        unsafe {
            pdf(light, dirs, &mut pdfs);
            rad(light, dirs, &mut radiance);
            sample(light, xi, &mut samples);
        }
        (pdfs, radiance, samples)
    }

    /// Whether this CPU runs kernels compiled for `width`.
    fn supports(width: VectorWidth) -> bool {
        match width {
            VectorWidth::Baseline => true,
            #[cfg(target_arch = "x86_64")]
            VectorWidth::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            #[cfg(target_arch = "x86_64")]
            VectorWidth::Avx512 => VectorWidth::widest() == VectorWidth::Avx512,
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }
}
