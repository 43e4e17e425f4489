//! The shade stage on the host: the scene data it reads (materials, lights and their BVH, the
//! LTC table, triangles by (instance, primitive)), the CPU executor over the kernels' stage
//! functions, and the per-pixel accumulation of `U`, `U_N`, `S_N` for the ratio estimator.

use crate::backend::{Backend, StageReport};
use crate::cpu::count;
use crate::error::{Error, Result};
use crate::lights::{trail_leaf, wants_bvh, LightBvh};
use crate::lit_sample::{shade_and_occlude, LitSample};
use crate::scene::{Material, Scene, SceneIdentity};
use crate::stream::{HitStream, RayStream, ShadeStream};
use glam::{DVec3, UVec2, Vec3, Vec4, Vec4Swizzles};
use rayon::prelude::*;
use raywave_kernels::sampling::light_select::{light_bounds, LightSet};
use raywave_kernels::shade::ltc::LTC_TABLE_LEN;
use raywave_kernels::shade::stage::{composite, resolve_surface, shade_sample, ShadeScene, Surface};
use raywave_shared::light::light_kind;
use raywave_shared::ltc_table::packed_entries;
use raywave_shared::{Light, LightBounds, LightBvhNode, MaterialParams, SamplerParams, ShadeParams};
use std::sync::atomic::{AtomicU64, Ordering};

/// Everything the shade stage reads about a scene, laid out as its buffers.
///
/// Backends that keep this data on a device (Vulkan) upload it on the first `shade` call and reuse
/// it while the same `ShadeData` is passed: its identity ([`ShadeData::identity`]) is a number
/// unique to the value plus the address and length of every buffer. Only a new `ShadeData` (a new
/// number) is sure to be uploaded again: a vector whose length changed is noticed, but one
/// replaced by another of the same length may sit at the old one's freed address, and values
/// edited in place change neither. To change any buffer's contents, build a new `ShadeData`.
///
/// It belongs to the scene it was built from ([`ShadeData::scene`]): a backend with a scene
/// loaded shades only data built from that scene or a clone of it, and refuses any other
/// ([`Error::SceneMismatch`]) — the trace runs against the loaded scene, so after loading a
/// rebuilt scene (an object moved) the old data would shade its hits with old triangles and
/// materials. Build the data again after each `load_scene` of a new scene. Edits to the public
/// fields (an engine's own lights, [`Light::NO_MESH`]) keep the scene.
pub struct ShadeData {
    /// Material per instance (mesh).
    pub materials: Vec<MaterialParams>,
    /// The quad lights. One made of a scene mesh names it ([`Light::made_of`]) and lights nothing
    /// of it; a light an engine adds keeps [`Light::NO_MESH`].
    pub lights: Vec<Light>,
    /// Light BVH nodes (empty: linear importance scan, for few lights).
    pub light_nodes: Vec<LightBvhNode>,
    /// Per light, its trail in the BVH (empty without a BVH).
    pub light_trails: Vec<u32>,
    /// The LTC table: first-lobe matrices, second-lobe matrices, then amplitudes
    /// ([`LTC_TABLE_LEN`] entries).
    pub ltc: Vec<Vec4>,
    /// Three vertices per triangle, instances one after the other.
    pub triangles: Vec<Vec4>,
    /// Index of each instance's first triangle in `triangles / 3`.
    pub first_triangle: Vec<u32>,
    /// Whether `U_S` takes the quadrature residual towards GGX ([`ShadeParams::analytic_residual`]);
    /// off by default.
    pub analytic_residual: bool,
    /// Unique per value (see [`ShadeData::identity`]).
    serial: u64,
    /// The scene this data was built from.
    scene: SceneIdentity,
}

/// The scene, the switch and each buffer's length (in elements) — not the contents: the LTC
/// table alone is 192 KiB and a large scene's triangles many MiB, which a log line or a failed
/// assertion would otherwise print whole.
impl std::fmt::Debug for ShadeData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShadeData")
            .field("scene", &self.scene)
            .field("serial", &self.serial)
            .field("materials", &self.materials.len())
            .field("lights", &self.lights.len())
            .field("light_nodes", &self.light_nodes.len())
            .field("light_trails", &self.light_trails.len())
            .field("ltc_entries", &self.ltc.len())
            .field("triangle_vertices", &self.triangles.len())
            .field("first_triangle", &self.first_triangle.len())
            .field("analytic_residual", &self.analytic_residual)
            .finish()
    }
}

/// What identifies the contents of a [`ShadeData`] for a backend's upload cache: a number unique
/// to the value, and the address and length of each of its buffers.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct ShadeDataIdentity {
    serial: u64,
    buffers: [(usize, usize); 7],
}

impl ShadeData {
    /// Lays out `scene` for the shade stage; a light BVH is built when the scene has many lights.
    pub fn new(scene: &Scene) -> Result<Self> {
        let materials = scene
            .meshes()
            .iter()
            .map(|m| MaterialParams {
                base_color_roughness: m.material.base_color.extend(m.material.roughness),
                emission_metallic: m.material.emission.extend(m.material.metallic),
                two_sided_emission: u32::from(m.material.double_sided),
                padding: [0; 3],
            })
            .collect();
        let lights = scene.lights().to_vec();
        let (light_nodes, light_trails) = if wants_bvh(lights.len()) {
            let bvh = LightBvh::build(&lights)?;
            (bvh.nodes().to_vec(), bvh.trails().to_vec())
        } else {
            (Vec::new(), Vec::new())
        };
        let mut triangles = Vec::with_capacity(scene.triangle_count() * 3);
        let mut first_triangle = Vec::with_capacity(scene.meshes().len());
        for mesh in scene.meshes() {
            first_triangle.push((triangles.len() / 3) as u32);
            for t in &mesh.triangles {
                triangles.extend(t.map(|v| mesh.positions[v as usize].extend(0.0)));
            }
        }
        let ltc = packed_entries().map(Vec4::from_array).collect();
        static SERIAL: AtomicU64 = AtomicU64::new(0);
        let serial = SERIAL.fetch_add(1, Ordering::Relaxed);
        Ok(Self {
            materials,
            lights,
            light_nodes,
            light_trails,
            ltc,
            triangles,
            first_triangle,
            analytic_residual: false,
            serial,
            scene: scene.identity().clone(),
        })
    }

    /// Checks what the shade stage assumes of this data, whose fields are public so that an
    /// engine can adjust what [`ShadeData::new`] laid out before the value's first `shade` (a
    /// device backend uploads them then; later changes need a new `ShadeData`: see its upload
    /// note): each material in the ranges [`Scene::new`] enforces and at least one per instance, the
    /// lights valid ([`crate::lights::validate_lights`]) and quads, a trail per light where
    /// there is a light BVH and each light that emits at the end of its trail, in a leaf with its
    /// own bounds (lights changed after the build need a new BVH: a moved light whose leaf still
    /// holds its old bounds is refused; an interior node's stale bounds are not looked at, but
    /// every node's bounds must be finite with a power `φ ≥ 0`), the
    /// LTC table complete ([`LTC_TABLE_LEN`] entries), three vertices
    /// per triangle and the instances' first triangles ascending within them. Every backend's
    /// `shade` calls it; an error names the field.
    pub fn check(&self) -> Result<()> {
        let invalid = |name, reason: String| Err(Error::InvalidParameter { name, reason });
        for (index, m) in self.materials.iter().enumerate() {
            let material = Material {
                base_color: m.base_color_roughness.xyz(),
                roughness: m.base_color_roughness.w,
                metallic: m.emission_metallic.w,
                emission: m.emission_metallic.xyz(),
                double_sided: m.two_sided_emission == 1,
            };
            if let Err((name, reason)) = material.check() {
                return invalid(name, format!("shade data materials[{index}] {reason}"));
            }
            if m.two_sided_emission > 1 {
                let reason = format!("shade data materials[{index}]: {} is neither 0 nor 1", m.two_sided_emission);
                return invalid("material.two_sided_emission", reason);
            }
        }
        crate::lights::validate_lights(&self.lights)?;
        if let Some(index) = self.lights.iter().position(|light| light.kind != light_kind::QUAD) {
            let reason = format!("lights[{index}] is a sphere; the shade stage integrates quad lights only");
            return invalid("light.kind", reason);
        }
        if !self.light_nodes.is_empty() && self.light_trails.len() != self.lights.len() {
            let reason = format!(
                "{} trails for {} lights (one per light with a BVH)",
                self.light_trails.len(),
                self.lights.len()
            );
            return invalid("light_trails", reason);
        }
        let unsound = |b: &LightBounds| {
            let finite = b.min.is_finite() && b.max.is_finite() && b.axis.is_finite();
            !(finite && b.phi >= 0.0 && b.phi.is_finite() && b.cos_theta_o.is_finite() && b.cos_theta_e.is_finite())
        };
        if let Some(index) = self.light_nodes.iter().position(|node| unsound(&node.bounds)) {
            // The selection's importances are products of these: a NaN or ∞ made its pmfs NaN.
            let reason = format!("light_nodes[{index}]'s bounds are not finite with a power ≥ 0");
            return invalid("light_nodes", reason);
        }
        if !self.light_nodes.is_empty() {
            // Every light of power in the tree, at the end of its trail, in a leaf with its bounds
            // (bit for bit): a light brightened, added or reordered after the build was never
            // drawn while `U` counted it (`U_N` biased), and a moved one was weighed where it had
            // been (pmf 0 where it now shines).
            let lost = self.lights.iter().zip(&self.light_trails).enumerate().find(|&(index, (light, &trail))| {
                let bounds = light_bounds(light);
                bounds.phi > 0.0
                    && !trail_leaf(&self.light_nodes, trail).is_some_and(|leaf| {
                        leaf.child_or_light == index as u32
                            && bytemuck::bytes_of(&leaf.bounds) == bytemuck::bytes_of(&bounds)
                    })
            });
            if let Some((index, _)) = lost {
                let reason = format!(
                    "lights[{index}] emits but its trail does not lead to its leaf with its bounds: the light BVH \
                     was built for other lights (build it again with LightBvh::build after changing them)"
                );
                return invalid("light_nodes", reason);
            }
        }
        if self.materials.len() < self.first_triangle.len() {
            let reason = format!(
                "{} materials for {} instances (at least one per instance)",
                self.materials.len(),
                self.first_triangle.len()
            );
            return invalid("materials", reason);
        }
        if self.ltc.len() != LTC_TABLE_LEN as usize {
            return invalid("ltc", format!("{} entries; the table has {LTC_TABLE_LEN}", self.ltc.len()));
        }
        let triangle_count = self.triangles.len() / 3;
        let ascending = self.first_triangle.windows(2).all(|w| w[0] <= w[1]);
        let within = self.first_triangle.last().is_none_or(|&last| last as usize <= triangle_count);
        if !self.triangles.len().is_multiple_of(3) || !ascending || !within || u32::try_from(triangle_count).is_err() {
            let reason = format!(
                "{} vertices (three per triangle) and first triangles {:?}… (ascending, at most the triangle count)",
                self.triangles.len(),
                &self.first_triangle[..self.first_triangle.len().min(8)]
            );
            return invalid("triangles", reason);
        }
        Ok(())
    }

    /// The scene this data was built from ([`Scene::identity`]), kept through edits of the
    /// public fields.
    pub fn scene(&self) -> &SceneIdentity {
        &self.scene
    }

    /// Checks that this data was built from `loaded`, the scene a backend has loaded (or a clone
    /// of it): [`Error::SceneMismatch`] naming both otherwise. `None` — no scene loaded, the hits
    /// coming from an engine's own trace — accepts the data of any scene. Every backend's `shade`
    /// calls it ([`crate::backend::check_shade_inputs`]).
    pub fn check_scene(&self, loaded: Option<&SceneIdentity>) -> Result<()> {
        match loaded {
            Some(loaded) if *loaded != self.scene => {
                Err(Error::SceneMismatch { data: self.scene.to_string(), loaded: loaded.to_string() })
            }
            _ => Ok(()),
        }
    }

    /// This value's identity for upload caches: the same `ShadeData` value with buffers of the
    /// same addresses and lengths. A different identity means the buffers must be uploaded again;
    /// an equal one means the same value, not necessarily the same contents (see [`ShadeData`]).
    pub fn identity(&self) -> ShadeDataIdentity {
        fn buffer<T>(v: &[T]) -> (usize, usize) {
            (v.as_ptr() as usize, v.len())
        }
        ShadeDataIdentity {
            serial: self.serial,
            buffers: [
                buffer(&self.materials),
                buffer(&self.lights),
                buffer(&self.light_nodes),
                buffer(&self.light_trails),
                buffer(&self.ltc),
                buffer(&self.triangles),
                buffer(&self.first_triangle),
            ],
        }
    }

    /// Shade-stage parameters for sample `sample_index` of a `width × height` frame drawn by
    /// `sampler`, with this scene's light counts and [`ShadeData::analytic_residual`] choice.
    pub fn params(&self, sampler: SamplerParams, width: u32, height: u32, sample_index: u32) -> ShadeParams {
        ShadeParams {
            sampler,
            width,
            // Saturating: a count that does not fit fails `Backend::shade`'s check, never wraps.
            count: width.saturating_mul(height),
            sample_index,
            light_count: self.lights.len() as u32,
            light_node_count: self.light_nodes.len() as u32,
            analytic_residual: u32::from(self.analytic_residual),
            padding: [0; 2],
        }
    }

    /// The kernels' view of this data, with every light and node valid (see
    /// [`ShadeData::view_for`] for the view a dispatch with given parameters sees).
    pub fn view(&self) -> ShadeScene<'_> {
        ShadeScene {
            materials: &self.materials,
            lights: LightSet::new(&self.lights, &self.light_nodes, &self.light_trails),
            ltc: &self.ltc,
        }
    }

    /// The kernels' view of this data as the shade entry point builds it from `params`: the valid
    /// light and node counts are `params.light_count` and `params.light_node_count` (clamped to
    /// the buffers by `LightSet`).
    pub fn view_for(&self, params: &ShadeParams) -> ShadeScene<'_> {
        let mut scene = self.view();
        scene.lights.light_count = params.light_count;
        scene.lights.node_count = params.light_node_count;
        scene
    }
}

/// The resolve step on the CPU: the surface each camera ray hit. Panics, like slice indexing, if
/// `hits` holds fewer records than `rays` ([`Backend::shade`] checks its streams first).
pub fn resolve(data: &ShadeData, rays: &RayStream, hits: &HitStream) -> Vec<Surface> {
    (0..rays.len())
        .into_par_iter()
        .map(|i| {
            resolve_surface(
                rays.direction[i].xyz(),
                hits.t[i],
                hits.instance[i],
                hits.primitive[i],
                hits.barycentrics[i],
                &data.triangles,
                &data.first_triangle,
            )
        })
        .collect()
}

/// The shade stage on the CPU: one record of the kernels' `shade_sample` per camera ray (ray `i`
/// is pixel `i`), written field by field into a [`ShadeStream`] — what the Vulkan entry point
/// writes into its five output buffers — and the count of samples that replaced a non-finite
/// value ([`crate::backend::StageReport::sanitized`]). Panics, like slice indexing, if `rays`
/// holds fewer rays than `surfaces` ([`Backend::shade`] checks its streams and `data` first).
pub fn shade(params: &ShadeParams, data: &ShadeData, rays: &RayStream, surfaces: &[Surface]) -> (ShadeStream, u64) {
    let scene = data.view_for(params);
    let width = params.width.max(1);
    let sanitized = AtomicU64::new(0);
    let mut out = ShadeStream::zeroed(surfaces.len());
    (&mut out.analytic, &mut out.unshadowed, &mut out.emitted, &mut out.shadow_origin, &mut out.shadow_direction)
        .into_par_iter()
        .enumerate()
        .for_each(|(i, (analytic, unshadowed, emitted, shadow_origin, shadow_direction))| {
            let pixel = UVec2::new(i as u32 % width, i as u32 / width);
            let s = count(shade_sample(params, pixel, rays.direction[i].xyz(), &surfaces[i], &scene), &sanitized);
            (*analytic, *unshadowed, *emitted) = (s.analytic, s.unshadowed, s.emitted);
            (*shadow_origin, *shadow_direction) = (s.shadow_origin, s.shadow_direction);
        });
    (out, sanitized.into_inner())
}

/// Shadow rays of a pass's shade stream, ready for the occlusion trace (ray `i` is pixel `i`).
pub fn shadow_rays(shades: &ShadeStream) -> RayStream {
    RayStream {
        origin: shades.shadow_origin.clone(),
        direction: shades.shadow_direction.clone(),
        pixel: (0..shades.len() as u32).collect(),
    }
}

/// Per-pixel means over the samples of a frame: the inputs of the ratio estimator and of the
/// denoiser. The sums are `f64`: summed in `f32`, 4 096 samples of the same `U` (a fixed
/// G-buffer, as `raywave report shade`'s reference draws them) averaged to within ~3·10⁻⁵ of
/// `U`, not to `U` (`report shade`'s lit-pixel RMSE, of that order, stayed as it was: it has
/// another cause). 48 bytes a pixel more than `f32` sums (177 MB at 2560×1440). The means are
/// `f32` again, what the denoiser and the composites take.
#[derive(Clone, Debug, Default)]
pub struct ShadeAccumulator {
    samples: u32,
    /// Samples and shadow rays the passes' stages sanitized ([`StageReport::sanitized`]).
    sanitized: u64,
    /// Σ analytic `U` (the same every sample on a fixed G-buffer; else varying with the ray's
    /// sub-pixel position).
    analytic: Vec<DVec3>,
    /// Σ `U_N` contributions.
    unshadowed: Vec<DVec3>,
    /// Σ `S_N` contributions.
    shadowed: Vec<DVec3>,
    /// Σ emitted radiance.
    emitted: Vec<DVec3>,
}

impl ShadeAccumulator {
    /// An empty accumulator for `pixels` pixels.
    pub fn new(pixels: usize) -> Self {
        let zero = vec![DVec3::ZERO; pixels];
        Self {
            samples: 0,
            sanitized: 0,
            analytic: zero.clone(),
            unshadowed: zero.clone(),
            shadowed: zero.clone(),
            emitted: zero,
        }
    }

    /// Runs one shade pass on `backend` — shade `rays`/`hits`, trace the shadow rays for
    /// occlusion — and adds it. Returns the two stages' timings and the bytes of the streams the
    /// pass used (shade stream, shadow rays, occlusion).
    pub fn shade_pass(
        &mut self,
        backend: &mut dyn Backend,
        params: &ShadeParams,
        data: &ShadeData,
        rays: &RayStream,
        hits: &HitStream,
    ) -> Result<([StageReport; 2], u64)> {
        let (shades, occluded, reports, bytes) = shade_and_occlude(backend, params, data, rays, hits)?;
        self.add(&shades, &occluded)?;
        self.sanitized += StageReport::total_sanitized(&reports);
        Ok((reports, bytes))
    }

    /// Adds one lit sample ([`crate::Backend::lit_sample`]) as [`Self::add`] adds a pass, with
    /// the same checks, and counts what its shade and occlusion stages sanitized.
    pub fn add_sample(&mut self, sample: &LitSample) -> Result<()> {
        self.add_records(&sample.analytic, &sample.unshadowed, &sample.emitted, &sample.occluded)?;
        self.sanitized += StageReport::total_sanitized(&sample.pass_timings);
        Ok(())
    }

    /// Adds one pass: its shade stream and the occlusion of its shadow rays (1 = blocked), both
    /// one record per pixel of this accumulator, with `U`, `U_N` and the emitted radiance finite
    /// and ≥ 0 as the shade stage writes them (an error otherwise, naming the first record at
    /// fault, and nothing is added: a NaN `U_N` had turned into a fully lit ratio pixel and a
    /// black stochastic one without a word).
    pub fn add(&mut self, shades: &ShadeStream, occluded: &[u32]) -> Result<()> {
        shades.check("accumulate")?;
        self.add_records(&shades.analytic, &shades.unshadowed, &shades.emitted, occluded)
    }

    /// [`Self::add`] of a pass's three accumulated fields, whose lengths are checked here.
    fn add_records(
        &mut self,
        analytic: &[Vec4],
        unshadowed: &[Vec4],
        emitted: &[Vec4],
        occluded: &[u32],
    ) -> Result<()> {
        let pixels = self.analytic.len();
        if [analytic.len(), unshadowed.len(), emitted.len(), occluded.len()] != [pixels; 4] {
            let reason = format!(
                "{} / {} / {} analytic / unshadowed / emitted records and {} occlusion results for an \
                 accumulator of {pixels} pixels",
                analytic.len(),
                unshadowed.len(),
                emitted.len(),
                occluded.len()
            );
            return Err(Error::InvalidParameter { name: "accumulate", reason });
        }
        // One pass over the three fields; the field at fault is named afterwards.
        let unsound = |v: &Vec4| !(v.xyz().is_finite() && v.xyz().min_element() >= 0.0);
        let records = analytic.par_iter().zip(unshadowed).zip(emitted);
        if let Some(record) = records.position_first(|((u, u_n), e)| unsound(u) || unsound(u_n) || unsound(e)) {
            let fields = [("analytic", analytic), ("unshadowed", unshadowed), ("emitted", emitted)];
            if let Some((field, values)) = fields.into_iter().find(|(_, values)| unsound(&values[record])) {
                let reason = format!("shade record {record}: {field} {} is not finite and ≥ 0", values[record].xyz());
                return Err(Error::InvalidParameter { name: "accumulate", reason });
            }
        }
        self.samples += 1;
        // Each pixel on its own, in parallel: a serial loop over 96 bytes a pixel was the slowest
        // part of a CPU pass's bookkeeping.
        let sums =
            self.analytic.par_iter_mut().zip(&mut self.unshadowed).zip(&mut self.shadowed).zip(&mut self.emitted);
        let passes = analytic.par_iter().zip(unshadowed).zip(emitted).zip(occluded);
        sums.zip(passes).for_each(|((((analytic, unshadowed), shadowed), emitted), (((u, u_n), e), &blocked))| {
            let u_n = u_n.xyz().as_dvec3();
            *analytic += u.xyz().as_dvec3();
            *unshadowed += u_n;
            if blocked == 0 {
                *shadowed += u_n;
            }
            *emitted += e.xyz().as_dvec3();
        });
        Ok(())
    }

    /// Values the shade and occlusion stages of this accumulator's [`Self::shade_pass`]es and
    /// [`Self::add_sample`]s sanitized — shade samples and shadow rays that went non-finite
    /// ([`StageReport::sanitized`]); 0 on sound input.
    pub fn sanitized(&self) -> u64 {
        self.sanitized
    }

    /// Samples (shade passes) added so far: the `N` of `U_N` and `S_N`.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    fn mean(&self, sums: &[DVec3]) -> Vec<Vec3> {
        let samples = f64::from(self.samples.max(1));
        sums.iter().map(|&s| (s / samples).as_vec3()).collect()
    }

    /// Per-pixel `U`.
    pub fn analytic(&self) -> Vec<Vec3> {
        self.mean(&self.analytic)
    }

    /// Per-pixel `U_N`.
    pub fn unshadowed(&self) -> Vec<Vec3> {
        self.mean(&self.unshadowed)
    }

    /// Per-pixel `S_N`.
    pub fn shadowed(&self) -> Vec<Vec3> {
        self.mean(&self.shadowed)
    }

    /// Per-pixel emitted radiance.
    pub fn emitted(&self) -> Vec<Vec3> {
        self.mean(&self.emitted)
    }

    /// The ratio estimator's image: `emitted + U · S_N / U_N` (fallback `U` where `U_N ≈ 0`),
    /// and how many pixels [`composite`] replaced by their emitted radiance because the sum
    /// overflowed `f32` (never for scenes' values, which [`crate::scene::MAX_EMISSION`] bounds).
    pub fn ratio_image(&self) -> (Vec<Vec3>, u64) {
        let (u, u_n, s_n, e) = (self.analytic(), self.unshadowed(), self.shadowed(), self.emitted());
        let mut replaced = 0;
        let image = (0..u.len())
            .map(|i| {
                let pixel = composite(u[i], u_n[i], s_n[i], e[i]);
                replaced += u64::from(pixel.replaced);
                pixel.value
            })
            .collect();
        (image, replaced)
    }

    /// The fully stochastic image: `emitted + S_N`. Unlike [`Self::ratio_image`] it replaces and
    /// counts no overflow: with scenes' values, which [`crate::scene::MAX_EMISSION`] bounds, the
    /// sum stays far inside `f32`; records near `f32::MAX` given to [`Self::add`] can make it ∞.
    pub fn stochastic_image(&self) -> Vec<Vec3> {
        let (s_n, e) = (self.shadowed(), self.emitted());
        s_n.iter().zip(&e).map(|(&s, &e)| s + e).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A light BVH built for other lights — trails swapped, a light added or moved after the
    /// build — is refused, naming the field, and so is a shade pass over part of the tree: the
    /// lights it left out had never been drawn while `U` counted them, and a moved one was
    /// weighed where it had been.
    #[test]
    fn a_light_bvh_built_for_other_lights_is_refused() {
        let scene = Scene::load("builtin:cornell-light-grid").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        assert!(!data.light_nodes.is_empty() && data.check().is_ok());
        let refused = |data: &ShadeData| match data.check() {
            Err(Error::InvalidParameter { name, reason }) => (name, reason),
            other => panic!("expected the BVH refused, got {other:?}"),
        };
        let mut swapped = ShadeData::new(&scene).unwrap();
        swapped.light_trails.swap(0, 1);
        let (name, reason) = refused(&swapped);
        assert!(name == "light_nodes" && reason.contains("lights[0] emits"), "{name}: {reason}");
        let mut added = ShadeData::new(&scene).unwrap();
        added.lights.push(added.lights[3]);
        added.light_trails.push(added.light_trails[3]);
        let (name, reason) = refused(&added);
        assert!(name == "light_nodes" && reason.contains("lights[20]"), "{name}: {reason}");
        let mut moved = ShadeData::new(&scene).unwrap();
        moved.lights[5].position += Vec4::new(0.25, 0.0, 0.0, 0.0);
        let (name, reason) = refused(&moved);
        assert!(name == "light_nodes" && reason.contains("lights[5]"), "{name}: {reason}");
        // An interior node edited to a power or a box that is not finite.
        let edits: [fn(&mut LightBvhNode); 3] =
            [|n| n.bounds.phi = f32::INFINITY, |n| n.bounds.phi = f32::NAN, |n| n.bounds.min.x = f32::NEG_INFINITY];
        for edit in edits {
            let mut edited = ShadeData::new(&scene).unwrap();
            assert_eq!(edited.light_nodes[0].is_leaf, 0, "the root of 20 lights");
            edit(&mut edited.light_nodes[0]);
            let (name, reason) = refused(&edited);
            assert!(name == "light_nodes" && reason.contains("light_nodes[0]'s bounds"), "{name}: {reason}");
        }
        // A light without power may lie anywhere: the tree leaves it out.
        let mut dark = added;
        dark.lights[20].radiance = Vec4::ZERO;
        assert!(dark.check().is_ok());
        let params = crate::frame::generate_params(&scene, 4, 4, 1);
        let rays = crate::cpu::generate(&params).unwrap();
        let hits = crate::cpu::trace(&crate::cpu::CpuScene::build(&scene).unwrap(), &rays).unwrap();
        let mut cpu = crate::cpu::CpuBackend::new();
        let shade_params = data.params(params.sampler, 4, 4, 0);
        assert!(cpu.shade(&shade_params, &data, &rays, &hits).is_ok());
        let partial = ShadeParams { light_node_count: shade_params.light_node_count - 1, ..shade_params };
        let error = cpu.shade(&partial, &data, &rays, &hits).unwrap_err().to_string();
        assert!(error.contains("all or none"), "{error}");
    }

    #[test]
    fn identity_tells_values_and_edits_apart() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let (a, mut b) = (ShadeData::new(&scene).unwrap(), ShadeData::new(&scene).unwrap());
        assert_eq!(a.identity(), a.identity());
        assert_ne!(a.identity(), b.identity(), "two values of the same scene");
        let before = b.identity();
        b.lights.clear();
        assert_ne!(before, b.identity(), "a buffer's length changed");
    }

    /// `ShadeData`'s `Debug` (and so a `LitSampleRequest`'s) gives the buffers' lengths on one
    /// short line, not their contents.
    #[test]
    fn shade_data_debugs_as_its_buffer_lengths() {
        let scene = Scene::load("builtin:cornell-light-grid").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let text = format!("{data:?}");
        let lengths = format!(
            "lights: {}, light_nodes: {}, light_trails: {}, ltc_entries: {LTC_TABLE_LEN}, triangle_vertices: {}, \
             first_triangle: {}",
            data.lights.len(),
            data.light_nodes.len(),
            data.light_trails.len(),
            3 * scene.triangle_count(),
            scene.meshes().len()
        );
        assert!(text.contains(&lengths) && text.len() < 1024, "{text}");
    }

    #[test]
    fn cpu_shade_fills_every_field_and_the_accumulator_takes_the_stream() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let params = crate::frame::generate_params(&scene, 9, 7, 3);
        let rays = crate::cpu::generate(&params).expect("generate");
        let hits = crate::cpu::trace(&crate::cpu::CpuScene::build(&scene).unwrap(), &rays).expect("trace");
        let shade_params = data.params(params.sampler, 9, 7, 0);
        let (shades, sanitized) = shade(&shade_params, &data, &rays, &resolve(&data, &rays, &hits));
        assert_eq!(sanitized, 0);
        assert_eq!(shades.len(), 63);
        assert_eq!(shades.bytes(), 63 * 80);
        let lit = shades.analytic.iter().filter(|u| u.max_element() > 0.0).count();
        assert!(lit > 30, "{lit} of 63 pixels lit");
        // Each field is written: a pixel whose camera ray hit holds a unit shadow ray leaving its
        // hit point, and most of them a positive `U_N` sample; emission is finite and ≥ 0.
        let (mut traced, mut sampled) = (0, 0);
        for i in 0..63 {
            let (origin, direction) = (shades.shadow_origin[i], shades.shadow_direction[i]);
            assert!(shades.emitted[i].is_finite() && shades.emitted[i].min_element() >= 0.0, "pixel {i}");
            if hits.primitive[i] == raywave_shared::stream::NO_HIT || direction.w == 0.0 {
                continue;
            }
            let hit_point = rays.origin[i].xyz() + hits.t[i] * rays.direction[i].xyz();
            assert!(origin.xyz().distance(hit_point) < 1e-3, "pixel {i}: {origin} vs {hit_point}");
            assert!((direction.xyz().length() - 1.0).abs() < 1e-5 && direction.w > 0.0, "pixel {i}: {direction}");
            traced += 1;
            sampled += usize::from(shades.unshadowed[i].max_element() > 0.0);
        }
        assert!(traced > 30 && sampled > 20, "{traced} shadow rays, {sampled} positive U_N samples of 63 pixels");
        // The occlusion trace's rays are those shadow rays, ray i for pixel i.
        let shadow = shadow_rays(&shades);
        assert!(shadow.pixel.iter().copied().eq(0..63));
        assert_eq!((&shadow.origin, &shadow.direction), (&shades.shadow_origin, &shades.shadow_direction));
        let mut accumulator = ShadeAccumulator::new(63);
        accumulator.add(&shades, &vec![0; 63]).unwrap();
        let u_n: Vec<Vec3> = shades.unshadowed.iter().map(|v| v.xyz()).collect();
        assert_eq!((accumulator.unshadowed(), accumulator.shadowed()), (u_n.clone(), u_n));
    }

    /// 4 096 samples of the same values (`report shade`'s reference on a fixed G-buffer) average
    /// to exactly those values, which an `f32` sum does not.
    #[test]
    fn the_accumulator_averages_many_equal_samples_exactly() {
        let (u, u_n, e) = (Vec3::new(0.1, 0.3, 0.7), Vec3::new(0.37, 1.9, 0.011), Vec3::new(3.3, 0.0, 1e-3));
        let mut shades = ShadeStream::zeroed(2);
        shades.analytic.fill(u.extend(0.0));
        shades.unshadowed.fill(u_n.extend(0.0));
        shades.emitted.fill(e.extend(0.0));
        let mut accumulator = ShadeAccumulator::new(2);
        let samples = 4096;
        for _ in 0..samples {
            accumulator.add(&shades, &[0, 1]).unwrap();
        }
        assert_eq!(accumulator.samples(), samples);
        assert_eq!(accumulator.analytic(), [u, u]);
        assert_eq!(accumulator.unshadowed(), [u_n, u_n]);
        assert_eq!(accumulator.shadowed(), [u_n, Vec3::ZERO]);
        assert_eq!(accumulator.emitted(), [e, e]);
        let f32_mean = (0..samples).fold(Vec3::ZERO, |sum, _| sum + u) / samples as f32;
        assert_ne!(f32_mean, u, "the f32 sum this replaced rounds off");
    }

    /// Before any pass the means are 0, not 0/0: an accumulator of no samples (a G-buffer built
    /// before the first pass, `DenoiseInput::new` on it) gives finite zeros, and so do its images.
    #[test]
    fn an_empty_accumulator_averages_to_zeros() {
        let accumulator = ShadeAccumulator::new(2);
        assert_eq!(accumulator.samples(), 0);
        for means in [accumulator.analytic(), accumulator.unshadowed(), accumulator.shadowed(), accumulator.emitted()] {
            assert_eq!(means, [Vec3::ZERO; 2]);
        }
        assert_eq!(accumulator.ratio_image(), (vec![Vec3::ZERO; 2], 0));
        assert_eq!(accumulator.stochastic_image(), [Vec3::ZERO; 2]);
    }

    #[test]
    fn the_accumulator_refuses_unsound_records_and_counts_replaced_composites() {
        let mut shades = ShadeStream::zeroed(3);
        shades.analytic.fill(Vec4::new(1.0, 1.0, 1.0, 0.0));
        shades.unshadowed.fill(Vec4::new(0.5, 0.5, 0.5, 0.0));
        let mut accumulator = ShadeAccumulator::new(3);
        for (field, value) in [("unshadowed", f32::NAN), ("analytic", -1.0), ("emitted", f32::INFINITY)] {
            let mut bad = shades.clone();
            let values = match field {
                "unshadowed" => &mut bad.unshadowed,
                "analytic" => &mut bad.analytic,
                _ => &mut bad.emitted,
            };
            values[2].y = value;
            let err = accumulator.add(&bad, &[0; 3]).unwrap_err().to_string();
            assert!(err.contains(&format!("shade record 2: {field}")), "{err}");
            assert_eq!(accumulator.samples(), 0, "nothing added");
        }
        // Finite values whose composite `U·S_N/U_N + E` overflows: replaced, and counted.
        shades.analytic[1] = Vec4::new(3e38, 1.0, 1.0, 0.0);
        shades.emitted[1] = Vec4::new(3e38, 0.0, 0.0, 0.0);
        accumulator.add(&shades, &[0; 3]).unwrap();
        let (image, replaced) = accumulator.ratio_image();
        assert_eq!(replaced, 1);
        assert!(image.iter().all(|c| c.is_finite()), "{image:?}");
    }
}
