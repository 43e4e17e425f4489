//! Lights on the host: validation and the light BVH that `raywave_kernels::sampling::light_select`
//! descends to choose one light among many.
//!
//! **Build.** A binary tree over the lights' bounds (`light_select::light_bounds`, the kernels' own
//! function, so host and kernels agree on every leaf), split top-down by the surface area
//! orientation heuristic (SAOH) of Conty Estevez & Kulla, "Importance Sampling of Many Lights with
//! Adaptive Tree Splitting" (HPG 2018), as pbrt-v4's `BVHLightSampler::buildBVH` evaluates it:
//! 12 buckets of centroids per axis, cost `Φ · M_Ω · K_r · area` per side with the orientation
//! measure `M_Ω = 2π(1 − cos θo) + π/2 · (2θw sin θo − cos(θo − 2θw) − 2θo sin θo + cos θo)`,
//! `θw = min(θo + θe, π)`, and `K_r` = longest extent / extent along the split axis. Where no
//! bucket split separates the lights (coincident centroids) the lights are halved by count.
//! One light per leaf.
//!
//! **Depth.** Trails have 32 bits, so leaves must sit at depth ≤ 32. SAOH splits can be
//! unbalanced; a split that would leave a child with more lights than a subtree of the remaining
//! depth holds is replaced by a count median along the widest centroid axis. Count medians alone
//! reach depth ⌈log₂ N⌉ ≤ 31 for the N ≤ 2³¹ lights of non-zero power that the nodes' `u32` indices
//! allow (2N − 1 nodes), so the guard always succeeds.
//!
//! **Node bounds.** Boxes are unions of the leaves' `f32` boxes (exact). Powers are summed in
//! `f64`. Normal cones are merged in `f64` as pbrt-v4's `DirectionCone` `Union` does, widened by
//! 10⁻⁵ rad and rounded towards the wider cone when stored as `f32`, so every node's bounds
//! contain its children's and its importance is positive wherever a light below it contributes.
//!
//! **Left out.** Lights of zero power (zero radiance) are left out of the tree: they can never
//! contribute. The walk gives them pmf 0 (their trail, 0, leads to another light's leaf);
//! `LightSet`'s uniform share still draws them, with pmf `1/(32 N)`, where they add 0 (the
//! scan's share, for scenes without a BVH, leaves them out). A scene whose lights all have zero
//! power gets an empty BVH; then `LightSet` falls back to the linear scan, which chooses
//! uniformly among them.
//!
//! **When.** [`wants_bvh`]: more than [`LINEAR_SCAN_MAX_LIGHTS`] = 8 lights. The scan evaluates
//! about 1.5·N importances per choice and gives every light its exact importance; the BVH
//! evaluates 2 per level with looser cluster bounds above the leaves. Measured once on the CPU
//! (release build, random spheres in a 20 m cube, random points; one run, so only the ratios
//! mean anything): per choice, scan / BVH = 134 / 78 ns at N = 2, 446 / 252 ns at 8, 868 / 300 ns
//! at 16, 3373 / 468 ns at 64; the BVH pmf's second moment `Σ I²/q / (Σ I)²` (1 for the scan) was
//! 1.19 at N = 8, 1.20 at 16, 1.37 at 64. Up to 8 lights the scan costs at most ≈ 0.2 µs more, small
//! next to the shadow ray it picks, for a ≈ 20 % lower second moment of that importance proxy;
//! beyond that its cost grows linearly.

use glam::{DVec3, Vec3, Vec4};
use raywave_kernels::sampling::light_select::{light_bounds, MAX_BVH_DEPTH};
use raywave_shared::light::{light_kind, Light, LightBounds, LightBvhNode};

use crate::error::{Error, Result};
use crate::scene::MAX_COORDINATE;

/// Most lights for which [`wants_bvh`] keeps the linear importance scan.
pub const LINEAR_SCAN_MAX_LIGHTS: usize = 8;

/// Whether a scene with `light_count` lights should select lights through a [`LightBvh`] (more
/// than [`LINEAR_SCAN_MAX_LIGHTS`]) rather than the linear importance scan.
pub fn wants_bvh(light_count: usize) -> bool {
    light_count > LINEAR_SCAN_MAX_LIGHTS
}

/// Buckets per axis of the SAOH split search (pbrt-v4's value).
const BUCKETS: usize = 12;

/// Angle by which merged normal cones are widened, covering rounding in the merge and in the
/// `f32` axis (≈ 10⁻⁷ rad).
const CONE_SLACK: f64 = 1e-5;

/// Checks one light: finite fields, a known kind, a non-negative radiance, an extent within the
/// scene coordinate limit ([`MAX_COORDINATE`]; a quad's far corner or a sphere's side beyond
/// `f32` had made the light BVH's boxes infinite, giving every light that shared a subtree with
/// it probability 0), and an area (positive) and a power that fit in `f32`. The error names the
/// field and the light's index.
pub fn validate_light(index: usize, light: &Light) -> Result<()> {
    let fields: [(&'static str, Vec4); 4] = [
        ("light.position", light.position),
        ("light.edge_u", light.edge_u),
        ("light.edge_v", light.edge_v),
        ("light.radiance", light.radiance),
    ];
    for (name, value) in fields {
        if !value.is_finite() {
            return Err(Error::InvalidParameter { name, reason: format!("light {index}: {value} is not finite") });
        }
    }
    let radiance = light.radiance.truncate();
    if radiance.min_element() < 0.0 {
        return Err(Error::InvalidParameter {
            name: "light.radiance",
            reason: format!("light {index}: radiance {radiance} has a negative component"),
        });
    }
    if light.two_sided > 1 {
        return Err(Error::InvalidParameter {
            name: "light.two_sided",
            reason: format!("light {index}: {} is neither 0 nor 1", light.two_sided),
        });
    }
    match light.kind {
        light_kind::SPHERE => {
            if light.position.w <= 0.0 {
                return Err(Error::InvalidParameter {
                    name: "light.position",
                    reason: format!("light {index}: sphere radius (position.w) {} is not positive", light.position.w),
                });
            }
            // The area in f32, as the kernels compute it: an infinite one gave an infinite power
            // blamed on the radiance, or (a dark light) a NaN power that let the light through.
            let radius = light.position.w;
            if !(4.0 * core::f32::consts::PI * radius * radius).is_finite() {
                return Err(Error::InvalidParameter {
                    name: "light.position",
                    reason: format!("light {index}: sphere radius (position.w) {radius} gives an area beyond f32"),
                });
            }
        }
        light_kind::QUAD => {
            let (edge_u, edge_v) = (light.edge_u.truncate(), light.edge_v.truncate());
            let area = edge_u.cross(edge_v).length();
            if !area.is_finite() {
                return Err(Error::InvalidParameter {
                    name: "light.edge_u",
                    reason: format!("light {index}: quad edges {edge_u} and {edge_v} span an area beyond f32"),
                });
            }
            if area <= 0.0 {
                return Err(Error::InvalidParameter {
                    name: "light.edge_u",
                    reason: format!(
                        "light {index}: quad edges {} and {} span zero area",
                        light.edge_u.truncate(),
                        light.edge_v.truncate()
                    ),
                });
            }
        }
        kind => {
            return Err(Error::InvalidParameter {
                name: "light.kind",
                reason: format!("light {index}: unknown kind {kind} (0 = sphere, 1 = quad)"),
            })
        }
    }
    let bounds = light_bounds(light);
    if let Err(extent) = reach_within_limit(&bounds) {
        return Err(Error::InvalidParameter {
            name: "light.position",
            reason: format!(
                "light {index}: reaches {extent:e} from the origin, beyond the coordinate limit {MAX_COORDINATE:e}"
            ),
        });
    }
    let phi = bounds.phi;
    if !phi.is_finite() {
        return Err(Error::InvalidParameter {
            name: "light.radiance",
            reason: format!("light {index}: emitted power overflows f32 (radiance {radiance})"),
        });
    }
    Ok(())
}

/// Whether the light of `bounds` (`light_bounds`, whose box holds a quad's corners rebuilt as
/// `position + edge_u + edge_v` in `f32`, as the kernels rebuild them) stays within
/// [`MAX_COORDINATE`] of the origin on every axis, with 8 ulps of slack: the rebuilt corners are
/// rounded twice more than the mesh vertices a light was fitted to, which may lie at the limit.
/// `Err` holds how far it reaches. [`validate_light`] refuses a light that does not; the scene's
/// derived lights are checked with it before they are made, so that such a light is no light
/// rather than a scene that fails to load.
pub(crate) fn reach_within_limit(bounds: &LightBounds) -> std::result::Result<(), f32> {
    let extent = bounds.min.truncate().abs().max(bounds.max.truncate().abs()).max_element();
    if extent.is_finite() && extent <= MAX_COORDINATE * (1.0 + 8.0 * f32::EPSILON) {
        Ok(())
    } else {
        Err(extent)
    }
}

/// Checks every light with [`validate_light`] and that their count fits the kernels' `u32`
/// indices (`u32::MAX` is the "no light" sentinel).
pub fn validate_lights(lights: &[Light]) -> Result<()> {
    if lights.len() >= u32::MAX as usize {
        return Err(Error::InvalidParameter {
            name: "lights",
            reason: format!("{} lights; at most {} are supported", lights.len(), u32::MAX - 1),
        });
    }
    lights.iter().enumerate().try_for_each(|(index, light)| validate_light(index, light))
}

/// The leaf `trail` leads to from the root of `nodes` (bit `d` of the trail: the second child at
/// depth `d`), or `None` where the path leaves the array or passes [`MAX_BVH_DEPTH`] — the walk
/// the kernels' `bvh_pmf` makes, without the probabilities.
pub(crate) fn trail_leaf(nodes: &[LightBvhNode], trail: u32) -> Option<&LightBvhNode> {
    let mut node = 0usize;
    for depth in 0..=MAX_BVH_DEPTH {
        let current = nodes.get(node)?;
        if current.is_leaf != 0 {
            return Some(current);
        }
        node = match trail.checked_shr(depth).map(|bits| bits & 1) {
            Some(0) => node + 1,
            Some(_) => current.child_or_light as usize,
            None => return None,
        };
    }
    None
}

/// A light BVH in the kernels' layout: depth-first nodes (node 0 the root; first child at
/// `index + 1`, second at `child_or_light`; a leaf's `child_or_light` is its light) and, per light,
/// its trail (bit `d` = 1 where the path takes the second child at depth `d`).
#[derive(Clone, Debug, Default)]
pub struct LightBvh {
    nodes: Vec<LightBvhNode>,
    trails: Vec<u32>,
    depth: u32,
}

/// Normal cone of a cluster (`f64`): unit axis `w`, half-angle `acos(cos_theta)`.
#[derive(Copy, Clone, Debug)]
struct Cone {
    w: DVec3,
    cos_theta: f64,
}

impl Cone {
    const ENTIRE_SPHERE: Cone = Cone { w: DVec3::Z, cos_theta: -1.0 };
}

/// `asin` clamped to its domain.
fn safe_asin(x: f64) -> f64 {
    x.clamp(-1.0, 1.0).asin()
}

/// Angle between unit vectors, accurate near 0 and π (pbrt-v4 `AngleBetween`).
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    if a.dot(b) < 0.0 {
        std::f64::consts::PI - 2.0 * safe_asin((a + b).length() / 2.0)
    } else {
        2.0 * safe_asin((b - a).length() / 2.0)
    }
}

/// The smallest cone (of pbrt-v4's construction) containing both cones.
fn cone_union(a: Cone, b: Cone) -> Cone {
    use std::f64::consts::PI;
    let theta_a = a.cos_theta.clamp(-1.0, 1.0).acos();
    let theta_b = b.cos_theta.clamp(-1.0, 1.0).acos();
    let theta_d = angle_between(a.w, b.w);
    // Where one cone holds the other, that one is kept, widened by the slack like a merged cone:
    // its axis is normalised again when stored in f32 (`Bounds::to_shared`), which can move it
    // by ~10⁻⁷ rad from a leaf's axis, whose cone may be a bare axis (θ = 0).
    // The merged cone below gets the same slack.
    let widened = |w: DVec3, theta: f64| {
        if theta + CONE_SLACK >= PI {
            Cone::ENTIRE_SPHERE
        } else {
            Cone { w, cos_theta: (theta + CONE_SLACK).cos() }
        }
    };
    if (theta_d + theta_b).min(PI) <= theta_a {
        return widened(a.w, theta_a);
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return widened(b.w, theta_b);
    }
    let theta_o = (theta_a + theta_d + theta_b) / 2.0;
    // Rotate a's axis towards b's by θo − θa about a × b (Rodrigues); then both cones touch the
    // merged one from inside, and the slack widens it beyond rounding.
    let k = a.w.cross(b.w);
    if k.length_squared() == 0.0 {
        return Cone::ENTIRE_SPHERE;
    }
    let k = k.normalize();
    let theta_r = theta_o - theta_a;
    let (sin, cos) = theta_r.sin_cos();
    let w = a.w * cos + k.cross(a.w) * sin + k * k.dot(a.w) * (1.0 - cos);
    widened(w.normalize(), theta_o)
}

/// Light bounds in `f64` for the build.
#[derive(Copy, Clone, Debug)]
struct Bounds {
    lo: DVec3,
    hi: DVec3,
    /// Bounding-sphere radius of the largest single light inside (`LightBounds::min.w`).
    light_radius: f64,
    /// Radius of a sphere about [`Bounds::centre`] that holds every light inside
    /// (`LightBounds::max.w`).
    radius: f64,
    phi: f64,
    cone: Cone,
    cos_theta_e: f64,
    two_sided: bool,
}

impl Bounds {
    fn from_light(b: &LightBounds) -> Self {
        Bounds {
            lo: b.min.truncate().as_dvec3(),
            hi: b.max.truncate().as_dvec3(),
            light_radius: b.min.w as f64,
            radius: b.max.w as f64,
            phi: b.phi as f64,
            cone: Cone { w: b.axis.truncate().as_dvec3(), cos_theta: b.cos_theta_o as f64 },
            cos_theta_e: b.cos_theta_e as f64,
            two_sided: b.two_sided != 0,
        }
    }

    fn union(&self, other: &Bounds) -> Bounds {
        let mut union = Bounds {
            lo: self.lo.min(other.lo),
            hi: self.hi.max(other.hi),
            light_radius: self.light_radius.max(other.light_radius),
            radius: 0.0,
            phi: self.phi + other.phi,
            cone: cone_union(self.cone, other.cone),
            cos_theta_e: self.cos_theta_e.min(other.cos_theta_e),
            two_sided: self.two_sided || other.two_sided,
        };
        // The lights lie in both children's spheres and in the union's box.
        let centre = union.centre();
        let spheres = [self, other].map(|b| (b.centre() - centre).length() + b.radius);
        let box_corner = (union.hi - centre).abs().max((centre - union.lo).abs()).length();
        union.radius = spheres[0].max(spheres[1]).min(box_corner);
        union
    }

    /// The box's centre as the kernels compute it from the `f32` corners (`importance`): the
    /// centre of the sphere `radius` is about.
    fn centre(&self) -> DVec3 {
        ((self.lo.as_vec3() + self.hi.as_vec3()) * 0.5).as_dvec3()
    }

    fn surface_area(&self) -> f64 {
        let d = self.hi - self.lo;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }

    /// SAOH cost of these bounds for a split along `axis` of the parent box `parent` (pbrt-v4
    /// `BVHLightSampler::EvaluateCost`).
    fn cost(&self, parent: &Bounds, axis: usize) -> f64 {
        use std::f64::consts::PI;
        let cos_o = self.cone.cos_theta.clamp(-1.0, 1.0);
        let theta_o = cos_o.acos();
        let theta_e = self.cos_theta_e.clamp(-1.0, 1.0).acos();
        let theta_w = (theta_o + theta_e).min(PI);
        let sin_o = (1.0 - cos_o * cos_o).max(0.0).sqrt();
        let m_omega = 2.0 * PI * (1.0 - cos_o)
            + PI / 2.0 * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o + cos_o);
        let extent = parent.hi - parent.lo;
        let k_r = extent.max_element() / extent[axis];
        self.phi * m_omega * k_r * self.surface_area()
    }

    /// The kernels' `f32` bounds, rounded so that they still contain what these bounds contain.
    fn to_shared(self) -> LightBounds {
        let axis = self.cone.w.as_vec3();
        let axis = if axis.is_finite() && axis.length_squared() > 0.0 { axis.normalize() } else { Vec3::Z };
        LightBounds {
            min: self.lo.as_vec3().extend(self.light_radius as f32),
            max: self.hi.as_vec3().extend(round_up(self.radius)),
            axis: axis.extend(0.0),
            phi: (self.phi.min(f32::MAX as f64)) as f32,
            cos_theta_o: round_down(self.cone.cos_theta),
            cos_theta_e: round_down(self.cos_theta_e),
            two_sided: self.two_sided as u32,
        }
    }
}

/// The largest `f32` ≤ `x`, clamped to [−1, 1] (a cosine rounded towards the wider angle).
fn round_down(x: f64) -> f32 {
    let x = x.clamp(-1.0, 1.0);
    let y = x as f32;
    if y as f64 > x {
        y.next_down().max(-1.0)
    } else {
        y
    }
}

/// The smallest `f32` ≥ `x` (a radius rounded towards the larger sphere).
fn round_up(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) < x {
        y.next_up()
    } else {
        y
    }
}

/// One light during the build.
#[derive(Copy, Clone, Debug)]
struct Item {
    light: u32,
    leaf: LightBounds,
    bounds: Bounds,
    centroid: DVec3,
}

impl LightBvh {
    /// Validates `lights` ([`validate_lights`]) and builds their BVH (module docs). No lights, or
    /// only lights of zero power, give an empty BVH, which selects nothing.
    pub fn build(lights: &[Light]) -> Result<LightBvh> {
        Self::build_with_depth(lights, MAX_BVH_DEPTH)
    }

    /// [`LightBvh::build`] with leaves at depth ≤ `max_depth` (≤ 32); lets tests force the
    /// depth guard with few lights.
    fn build_with_depth(lights: &[Light], max_depth: u32) -> Result<LightBvh> {
        validate_lights(lights)?;
        let mut items: Vec<Item> = lights
            .iter()
            .enumerate()
            .filter_map(|(index, light)| {
                let leaf = light_bounds(light);
                (leaf.phi > 0.0).then(|| {
                    let bounds = Bounds::from_light(&leaf);
                    Item { light: index as u32, leaf, bounds, centroid: (bounds.lo + bounds.hi) * 0.5 }
                })
            })
            .collect();
        let max_depth = max_depth.min(MAX_BVH_DEPTH);
        check_tree_size(items.len(), max_depth)?;
        let mut bvh = LightBvh { nodes: Vec::with_capacity(2 * items.len()), trails: vec![0; lights.len()], depth: 0 };
        if !items.is_empty() {
            bvh.build_node(&mut items, 0, 0, max_depth);
        }
        Ok(bvh)
    }

    /// Appends the subtree over `items` (at depth `depth`, reached by `trail`) and returns its bounds.
    fn build_node(&mut self, items: &mut [Item], depth: u32, trail: u32, max_depth: u32) -> Bounds {
        self.depth = self.depth.max(depth);
        if let [item] = items {
            self.trails[item.light as usize] = trail;
            self.nodes.push(LightBvhNode {
                bounds: item.leaf,
                child_or_light: item.light,
                is_leaf: 1,
                padding: [0; 2],
            });
            return item.bounds;
        }
        let index = self.nodes.len();
        self.nodes.push(bytemuck::Zeroable::zeroed());
        let mid = split(items, depth, max_depth);
        let (first, second) = items.split_at_mut(mid);
        let first_bounds = self.build_node(first, depth + 1, trail, max_depth);
        let second_index = self.nodes.len() as u32;
        let second_bounds = self.build_node(second, depth + 1, trail | 1 << depth, max_depth);
        let bounds = first_bounds.union(&second_bounds);
        self.nodes[index] =
            LightBvhNode { bounds: bounds.to_shared(), child_or_light: second_index, is_leaf: 0, padding: [0; 2] };
        bounds
    }

    /// The nodes, in the layout `select_bvh` reads; empty when no light has power.
    pub fn nodes(&self) -> &[LightBvhNode] {
        &self.nodes
    }

    /// Per light (indexed like the light list given to [`LightBvh::build`]), its trail.
    pub fn trails(&self) -> &[u32] {
        &self.trails
    }

    /// Depth of the deepest leaf (0 for a single leaf or an empty tree); at most 32.
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Whether the tree has no node (no light of non-zero power).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
}

/// Checks that `powered` lights (those of non-zero power) fit a light BVH whose leaves sit at
/// depth ≤ `max_depth` (≤ 32): at most `2^max_depth` leaves, and at most 2³¹, so that the
/// tree's `2·powered − 1` node indices fit the nodes' `u32` child index.
fn check_tree_size(powered: usize, max_depth: u32) -> Result<()> {
    let most = (1u64 << max_depth).min(1 << 31);
    if powered as u64 > most {
        return Err(Error::InvalidParameter {
            name: "lights",
            reason: format!(
                "{powered} lights of non-zero power do not fit a light BVH of depth {max_depth} whose node \
                 indices are u32 ({most} at most)"
            ),
        });
    }
    Ok(())
}

/// Bucket of `c` along `axis` among [`BUCKETS`] over `lo..hi` (pbrt-v4's bucketing).
fn bucket(c: DVec3, lo: DVec3, hi: DVec3, axis: usize) -> usize {
    let t = (c[axis] - lo[axis]) / (hi[axis] - lo[axis]);
    ((BUCKETS as f64 * t) as usize).min(BUCKETS - 1)
}

/// Reorders `items` (≥ 2) and returns the split point: the SAOH bucket split of least cost, or
/// a count median when there is none or it would break the depth limit.
fn split(items: &mut [Item], depth: u32, max_depth: u32) -> usize {
    let bounds = items[1..].iter().fold(items[0].bounds, |b, item| b.union(&item.bounds));
    let (c_lo, c_hi) = items
        .iter()
        .fold((items[0].centroid, items[0].centroid), |(lo, hi), i| (lo.min(i.centroid), hi.max(i.centroid)));

    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        if c_hi[axis] <= c_lo[axis] {
            continue;
        }
        let mut buckets: [Option<(Bounds, usize)>; BUCKETS] = [None; BUCKETS];
        for item in items.iter() {
            let b = &mut buckets[bucket(item.centroid, c_lo, c_hi, axis)];
            *b = Some(match b {
                Some((bounds, count)) => (bounds.union(&item.bounds), *count + 1),
                None => (item.bounds, 1),
            });
        }
        // Prefix unions from the left, suffix unions from the right.
        let mut below: [Option<(Bounds, usize)>; BUCKETS] = [None; BUCKETS];
        let mut above: [Option<(Bounds, usize)>; BUCKETS] = [None; BUCKETS];
        for i in 0..BUCKETS {
            below[i] = merge(if i > 0 { below[i - 1] } else { None }, buckets[i]);
            let j = BUCKETS - 1 - i;
            above[j] = merge(if j + 1 < BUCKETS { above[j + 1] } else { None }, buckets[j]);
        }
        for i in 0..BUCKETS - 1 {
            if let (Some((b0, _)), Some((b1, _))) = (below[i], above[i + 1]) {
                let cost = b0.cost(&bounds, axis) + b1.cost(&bounds, axis);
                if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, i));
                }
            }
        }
    }

    // A child at depth + 1 may hold at most 2^(max_depth − depth − 1) lights.
    let capacity = 1u64 << (max_depth - depth - 1);
    if let Some((_, axis, split_bucket)) = best {
        let mid = partition(items, |item| bucket(item.centroid, c_lo, c_hi, axis) <= split_bucket);
        let fits = (mid as u64) <= capacity && ((items.len() - mid) as u64) <= capacity;
        if mid > 0 && mid < items.len() && fits {
            return mid;
        }
    }
    // Count median along the widest centroid axis (any order when the centroids coincide).
    let axis = (c_hi - c_lo).max_position();
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
    mid
}

/// Union of two optional (bounds, count) pairs.
fn merge(a: Option<(Bounds, usize)>, b: Option<(Bounds, usize)>) -> Option<(Bounds, usize)> {
    match (a, b) {
        (Some((ba, ca)), Some((bb, cb))) => Some((ba.union(&bb), ca + cb)),
        (x, None) | (None, x) => x,
    }
}

/// Moves the items for which `first` holds to the front; returns how many there are.
fn partition(items: &mut [Item], first: impl Fn(&Item) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..items.len() {
        if first(&items[i]) {
            items.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::{chi_square_counts, ChiSquare};
    use glam::UVec3;
    use raywave_kernels::hash::{pcg3d, unit_float, CounterRng};
    use raywave_kernels::sampling::light_select::uniform_light_point;
    use raywave_kernels::sampling::light_select::{
        bvh_pmf, importance, importance_pmf, select_bvh, LightChoice, LightSet,
    };

    fn random_light(rng: &mut CounterRng, extent: f32) -> Light {
        let radiance = Vec3::new(rng.range(0.1, 5.0), rng.range(0.1, 5.0), rng.range(0.1, 5.0));
        let kind = rng.next_f32();
        if kind < 0.34 {
            Light::sphere(rng.vec3(-extent, extent), rng.range(0.05, 0.5), radiance)
        } else {
            let eu = rng.unit_vec3() * rng.range(0.1, 1.0);
            let ev = eu.cross(rng.unit_vec3()).normalize() * rng.range(0.1, 1.0);
            Light::quad(rng.vec3(-extent, extent), eu, ev, radiance, kind > 0.67)
        }
    }

    fn random_lights(seed: u32, count: usize, extent: f32) -> Vec<Light> {
        let mut rng = CounterRng::new(seed);
        (0..count).map(|_| random_light(&mut rng, extent)).collect()
    }

    fn contains(outer: &LightBounds, inner: &LightBounds) -> bool {
        outer.min.truncate().cmple(inner.min.truncate()).all()
            && outer.max.truncate().cmpge(inner.max.truncate()).all()
            && outer.min.w >= inner.min.w
            && {
                // The outer sphere holds the inner sphere or the inner box (up to the `f32`
                // rounding of the inner radius).
                let centre = |b: &LightBounds| ((b.min + b.max).truncate() * 0.5).as_dvec3();
                let (c_o, c_i) = (centre(outer), centre(inner));
                let (lo, hi) = (inner.min.truncate().as_dvec3(), inner.max.truncate().as_dvec3());
                let sphere = (c_i - c_o).length() + inner.max.w as f64;
                let box_corner = (hi - c_o).abs().max((c_o - lo).abs()).length();
                outer.max.w as f64 >= sphere.min(box_corner) * (1.0 - 1e-6)
            }
            && outer.phi >= inner.phi * (1.0 - 1e-6)
            && (outer.two_sided >= inner.two_sided)
            && outer.cos_theta_e <= inner.cos_theta_e
            && {
                // The inner cone lies within the outer one.
                let theta_o = (outer.cos_theta_o as f64).acos();
                let theta_i = (inner.cos_theta_o as f64).acos();
                let d = angle_between(outer.axis.truncate().as_dvec3(), inner.axis.truncate().as_dvec3());
                outer.cos_theta_o == -1.0 || d + theta_i <= theta_o + 1e-9
            }
    }

    /// Checks the layout: every light of non-zero power in exactly one leaf, reached by its trail;
    /// every interior node's bounds contain its children's; depth within the limit.
    fn check_structure(bvh: &LightBvh, lights: &[Light], max_depth: u32) {
        let nodes = bvh.nodes();
        let powered: Vec<u32> =
            (0..lights.len() as u32).filter(|&k| light_bounds(&lights[k as usize]).phi > 0.0).collect();
        assert_eq!(nodes.len(), (2 * powered.len()).saturating_sub(1));
        assert!(bvh.depth() <= max_depth);
        let mut seen = vec![0; lights.len()];
        for (i, node) in nodes.iter().enumerate() {
            if node.is_leaf == 1 {
                seen[node.child_or_light as usize] += 1;
                assert_eq!(node.bounds, light_bounds(&lights[node.child_or_light as usize]));
            } else {
                assert_eq!(node.is_leaf, 0);
                let second = node.child_or_light as usize;
                assert!(second > i + 1 && second < nodes.len());
                assert!(contains(&node.bounds, &nodes[i + 1].bounds), "node {i} vs {}", i + 1);
                assert!(contains(&node.bounds, &nodes[second].bounds), "node {i} vs {second}");
            }
        }
        for &k in &powered {
            assert_eq!(seen[k as usize], 1, "light {k}");
            let (mut node, mut depth) = (0usize, 0);
            while nodes[node].is_leaf == 0 {
                node = if (bvh.trails()[k as usize] >> depth) & 1 == 0 {
                    node + 1
                } else {
                    nodes[node].child_or_light as usize
                };
                depth += 1;
            }
            assert_eq!(nodes[node].child_or_light, k);
            assert!(depth <= bvh.depth());
        }
    }

    /// Whether some of 32 sampled points of `light` sends light to `p` with cosines above 10⁻⁴ at
    /// the emitter and (for `n ≠ 0`) at the receiver: a clearly positive unoccluded contribution.
    fn contributes(light: &Light, rng: &mut CounterRng, p: Vec3, n: Vec3) -> bool {
        if light.radiance.truncate() == Vec3::ZERO {
            return false;
        }
        (0..32).any(|_| {
            let (x, nx) = uniform_light_point(light, glam::Vec2::new(rng.next_f32(), rng.next_f32()));
            let w = (p - x).normalize_or_zero();
            let emit = if light.two_sided != 0 { nx.dot(w).abs() } else { nx.dot(w) };
            emit > 1e-4 && (n == Vec3::ZERO || n.dot(-w) > 1e-4)
        })
    }

    /// pmfs sum to 1 at random points; the pmf `select_bvh` returns is `bvh_pmf` of its light;
    /// every light that contributes has positive pmf. (A light whose own importance is positive
    /// may still get pmf 0 where it does not contribute: a cluster's sphere holds its children's
    /// boxes or their spheres, whichever is smaller, and its normal cone is a union's.)
    fn check_pmfs(bvh: &LightBvh, lights: &[Light], seed: u32, points: usize, extent: f32) {
        let mut rng = CounterRng::new(seed);
        for case in 0..points {
            let p = rng.vec3(-extent, extent);
            let n = if case % 4 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
            let pmfs: Vec<f32> =
                (0..lights.len() as u32).map(|k| bvh_pmf(lights, bvh.nodes(), bvh.trails(), p, n, k)).collect();
            let sum: f64 = pmfs.iter().map(|&q| q as f64).sum();
            assert!((sum - 1.0).abs() < 1e-4, "case {case}: sum {sum}");
            for (k, light) in lights.iter().enumerate() {
                if contributes(light, &mut rng, p, n) {
                    assert!(pmfs[k] > 0.0, "case {case}: light {k} contributes at {p}, {n} but has pmf 0");
                }
            }
            for _ in 0..4 {
                let choice = select_bvh(lights, bvh.nodes(), p, n, rng.next_f32());
                assert!(choice.is_valid());
                assert_eq!(choice.pmf, pmfs[choice.index as usize]);
            }
        }
    }

    /// Pearson's chi-square test ([`crate::stats::chi_square_counts`]) of `draws` selections at
    /// (p, n) against the pmf, after checking that no light of pmf 0 was chosen.
    fn chi_square(bvh: &LightBvh, lights: &[Light], p: Vec3, n: Vec3, draws: u32, seed: u32) -> ChiSquare {
        let pmfs: Vec<f64> =
            (0..lights.len() as u32).map(|k| bvh_pmf(lights, bvh.nodes(), bvh.trails(), p, n, k) as f64).collect();
        let mut counts = vec![0u64; lights.len()];
        for i in 0..draws {
            let choice = select_bvh(lights, bvh.nodes(), p, n, unit_float(pcg3d(UVec3::new(i, seed, 0x5e1)).x));
            assert!(choice.pmf > 0.0);
            counts[choice.index as usize] += 1;
        }
        let expected: Vec<f64> = pmfs.iter().map(|&q| q * f64::from(draws)).collect();
        let fit = chi_square_counts(&counts, &expected);
        assert_eq!(fit.zero_expected_samples, 0, "a light of pmf 0 was chosen");
        fit
    }

    #[test]
    fn lights_rejects_bad_input() {
        let good = Light::sphere(Vec3::ZERO, 1.0, Vec3::ONE);
        let q = Light::quad(Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE, false);
        let mut nan = good;
        nan.position.y = f32::NAN;
        let mut inf_edge = q;
        inf_edge.edge_v.x = f32::INFINITY;
        let mut kind = good;
        kind.kind = 5;
        let mut sided = q;
        sided.two_sided = 2;
        let huge_quad = |radiance| Light::quad(Vec3::ZERO, Vec3::X * 1e10, Vec3::Y * 1e10, radiance, false);
        let cases: [(Light, &str); 13] = [
            (nan, "light.position"),
            (inf_edge, "light.edge_v"),
            (Light::sphere(Vec3::ZERO, 1.0, Vec3::new(1.0, -0.5, 1.0)), "light.radiance"),
            (Light::sphere(Vec3::ZERO, 0.0, Vec3::ONE), "light.position"),
            (Light::sphere(Vec3::ZERO, -1.0, Vec3::ONE), "light.position"),
            (Light::quad(Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::ONE, false), "light.edge_u"),
            (kind, "light.kind"),
            (sided, "light.two_sided"),
            // An area of 10²⁰ fits f32 but the cross product's squared length does not: the size
            // is named, also for a dark light, whose power had been NaN.
            (huge_quad(Vec3::ONE), "light.edge_u"),
            (huge_quad(Vec3::ZERO), "light.edge_u"),
            (Light::sphere(Vec3::ZERO, 1e19, Vec3::ZERO), "light.position"),
            // Beyond the coordinate limit with a finite area and power: a far corner at ∞ in f32
            // had made every enclosing box of the light BVH infinite.
            (
                Light::quad(Vec3::new(f32::MAX, 0.0, -1.0), Vec3::X * 1e32, Vec3::Y * 1e-14, Vec3::ONE, false),
                "light.position",
            ),
            (Light::sphere(Vec3::new(0.0, 0.0, 9e7), 2e7, Vec3::ONE), "light.position"),
        ];
        for (bad, field) in cases {
            match LightBvh::build(&[good, bad, q]) {
                Err(Error::InvalidParameter { name, reason }) => {
                    assert_eq!(name, field);
                    assert!(reason.starts_with("light 1:"), "{reason}");
                }
                other => panic!("{bad:?}: expected an invalid {field}, got {other:?}"),
            }
        }
        let blinding = Light::sphere(Vec3::ZERO, 1e7, Vec3::splat(1e30));
        assert!(matches!(validate_light(0, &blinding), Err(Error::InvalidParameter { name: "light.radiance", .. })));
        assert!(validate_lights(&[good, q]).is_ok());
    }

    #[test]
    fn lights_empty_and_dark_scenes_select_nothing() {
        for lights in [vec![], vec![Light::sphere(Vec3::ZERO, 1.0, Vec3::ZERO); 3]] {
            let bvh = LightBvh::build(&lights).unwrap();
            assert!(bvh.is_empty() && bvh.nodes().is_empty());
            assert_eq!(bvh.trails().len(), lights.len());
            assert_eq!(select_bvh(&lights, bvh.nodes(), Vec3::ONE, Vec3::ZERO, 0.5), LightChoice::NONE);
            assert!((0..lights.len() as u32).all(|k| bvh_pmf(
                &lights,
                bvh.nodes(),
                bvh.trails(),
                Vec3::ONE,
                Vec3::ZERO,
                k
            ) == 0.0));
            // Through LightSet, an empty BVH means the linear scan: uniform among dark lights.
            let set = LightSet::new(&lights, bvh.nodes(), bvh.trails());
            let expected = if lights.is_empty() { LightChoice::NONE } else { LightChoice { index: 1, pmf: 1.0 / 3.0 } };
            assert_eq!(set.select(Vec3::ONE, Vec3::ZERO, glam::Vec2::splat(0.5)), expected);
        }
    }

    #[test]
    fn lights_bvh_of_one_two_three_lights() {
        let all = random_lights(5, 3, 3.0);
        for count in 1..=3 {
            let lights = &all[..count];
            let bvh = LightBvh::build(lights).unwrap();
            check_structure(&bvh, lights, MAX_BVH_DEPTH);
            assert_eq!(bvh.depth(), if count == 1 { 0 } else { (count - 1) as u32 });
            check_pmfs(&bvh, lights, 6, 500, 5.0);
        }
        // A single leaf is chosen with pmf 1 wherever p is, even with zero importance.
        let bvh = LightBvh::build(&all[..1]).unwrap();
        let behind = LightChoice { index: 0, pmf: 1.0 };
        assert_eq!(select_bvh(&all[..1], bvh.nodes(), Vec3::splat(100.0), Vec3::splat(1.0), 0.9), behind);
    }

    #[test]
    fn lights_bvh_of_a_thousand_lights() {
        let lights = random_lights(7, 1000, 20.0);
        let bvh = LightBvh::build(&lights).unwrap();
        check_structure(&bvh, &lights, MAX_BVH_DEPTH);
        assert!(bvh.depth() < 32, "depth {}", bvh.depth());
        check_pmfs(&bvh, &lights, 8, 200, 25.0);

        // Sampling frequencies match the pmf at a few points (10⁵ draws each).
        for (i, (p, n)) in
            [(Vec3::ZERO, Vec3::ZERO), (Vec3::new(3.0, -2.0, 5.0), Vec3::Y), (Vec3::splat(30.0), -Vec3::ONE)]
                .into_iter()
                .enumerate()
        {
            let fit = chi_square(&bvh, &lights, p, n, 100_000, i as u32);
            assert!(fit.dof >= 10 && fit.p_value > 0.001, "point {i}: {fit}");
        }
    }

    #[test]
    fn lights_bvh_frequencies_with_few_lights() {
        // Sixteen lights at p = (0.5, 0, 0.5), no surface: two quads face away (pmf 0, must never
        // be drawn; p lies inside the bounding sphere of one, where the shade stage's own side
        // test gives it 0), the other 14 pmfs are above 3·10⁻⁴ (expected counts ≥ 30), so the
        // chi-square has 13 dof.
        let lights = random_lights(11, 16, 2.0);
        let bvh = LightBvh::build(&lights).unwrap();
        let (p, n) = (Vec3::new(0.5, 0.0, 0.5), Vec3::ZERO);
        let fit = chi_square(&bvh, &lights, p, n, 100_000, 3);
        assert!(fit.dof == 13 && fit.p_value > 0.001, "{fit}");
    }

    /// A scene scaled by 10⁻³ or 10³ (lights and point alike) gets the same choice: the clamp of
    /// every node's importance is the bounding-sphere radius of its largest light, a length that
    /// scales with the scene (pbrt-v4 clamps the squared distance with half the box diagonal's
    /// length, which does not).
    #[test]
    fn lights_bvh_choice_does_not_depend_on_the_scene_scale() {
        let lights = random_lights(5, 40, 2.0);
        let bvh = LightBvh::build(&lights).unwrap();
        let mut rng = CounterRng::new(9);
        for scale in [1e-3f32, 1e3] {
            let scaled: Vec<Light> = lights
                .iter()
                .map(|l| Light {
                    position: l.position * scale,
                    edge_u: l.edge_u * scale,
                    edge_v: l.edge_v * scale,
                    ..*l
                })
                .collect();
            let scaled_bvh = LightBvh::build(&scaled).unwrap();
            for _ in 0..20 {
                let (p, n) = (rng.vec3(-2.0, 2.0), rng.unit_vec3());
                for k in 0..40 {
                    let pmf = bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, n, k);
                    let scaled_pmf = bvh_pmf(&scaled, scaled_bvh.nodes(), scaled_bvh.trails(), p * scale, n, k);
                    assert!(
                        (pmf - scaled_pmf).abs() <= 2e-3 * pmf.max(scaled_pmf) + 1e-9,
                        "×{scale}, light {k} at {p}: {pmf} against {scaled_pmf}"
                    );
                }
            }
        }
    }

    #[test]
    fn lights_importance_concentrates_on_nearby_lights() {
        // 1000 small downward-facing quads on a 40 × 25 ceiling grid, 1 m apart, 3 m up.
        let lights: Vec<Light> = (0..1000)
            .map(|k| {
                let (x, z) = ((k % 40) as f32, (k / 40) as f32);
                Light::quad(Vec3::new(x, 3.0, z), Vec3::X * 0.2, Vec3::Z * 0.2, Vec3::splat(10.0), false)
            })
            .collect();
        let bvh = LightBvh::build(&lights).unwrap();
        check_structure(&bvh, &lights, MAX_BVH_DEPTH);
        assert_eq!(light_bounds(&lights[0]).axis.truncate(), -Vec3::Y);
        for k in [0usize, 417, 999] {
            let centre = lights[k].position.truncate() + Vec3::new(0.1, 0.0, 0.1);
            // (point, normal, least pmf in multiples of the uniform 1/N): 0.3 m, 1 m and 3 m below.
            for (p, n, factor) in [
                (centre - Vec3::Y * 0.3, Vec3::Y, 100.0),
                (centre - Vec3::Y, Vec3::ZERO, 40.0),
                (centre - Vec3::Y * 3.0, Vec3::Y, 10.0),
            ] {
                let pmf = bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, n, k as u32);
                let linear = importance_pmf(&lights, p, n, k as u32);
                assert!(pmf > factor / 1000.0, "light {k} at {p}: BVH pmf {pmf} (linear {linear})");
                assert!(linear >= pmf, "light {k} at {p}: BVH pmf {pmf} (linear {linear})");
            }
            // Above the ceiling nothing is lit: every branch is 1/2, the pmfs still sum to 1.
            let above = centre + Vec3::Y;
            assert!((0..1000).all(|j| importance(&light_bounds(&lights[j]), above, Vec3::Y) == 0.0));
            let sum: f64 =
                (0..1000).map(|j| bvh_pmf(&lights, bvh.nodes(), bvh.trails(), above, Vec3::Y, j) as f64).sum();
            assert!((sum - 1.0).abs() < 1e-5, "{sum}");
        }
    }

    #[test]
    fn lights_depth_guard_and_coincident_lights() {
        // Lights spaced exponentially with power growing steeply invite unbalanced SAOH splits;
        // with a depth limit of 4 the 16 lights must end up in a perfectly balanced tree.
        let lights: Vec<Light> =
            (0..16).map(|k| Light::sphere(Vec3::X * 1.5f32.powi(k), 0.1, Vec3::splat(2.0f32.powi(k)))).collect();
        let unlimited = LightBvh::build(&lights).unwrap();
        check_structure(&unlimited, &lights, MAX_BVH_DEPTH);
        let bvh = LightBvh::build_with_depth(&lights, 4).unwrap();
        check_structure(&bvh, &lights, 4);
        assert_eq!(bvh.depth(), 4);
        check_pmfs(&bvh, &lights, 12, 200, 300.0);
        assert!(LightBvh::build_with_depth(&lights, 3).is_err());

        // Coincident lights: halved by count; every light equally likely.
        let same = vec![Light::quad(Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::ONE, true); 50];
        let bvh = LightBvh::build(&same).unwrap();
        check_structure(&bvh, &same, MAX_BVH_DEPTH);
        assert_eq!(bvh.depth(), 6);
        for p in [Vec3::new(0.5, 0.0, 0.5), Vec3::new(0.3, 2.0, 0.1), Vec3::new(4.0, -1.0, 0.0)] {
            let pmfs: Vec<f32> =
                (0..50).map(|k| bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, Vec3::ZERO, k)).collect();
            let (lo, hi) = pmfs.iter().fold((1.0f32, 0.0f32), |(lo, hi), &q| (lo.min(q), hi.max(q)));
            assert!(lo >= 1.0 / 64.0 && hi <= 1.0 / 32.0, "{lo} {hi}");
            assert!((pmfs.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn lights_bvh_parents_hold_tilted_parallel_children() {
        // Parallel quads whose f32 axis (normal / area) is not a fixed point of `normalize`: a
        // parent that kept a child's cone unwidened stored its axis normalised again, ~10⁻⁷ rad
        // away, around a bare axis (θ = 0) that no longer held the child's.
        let (edge_u, edge_v) =
            (Vec3::new(0.30318594, 0.5774467, -0.81228083), Vec3::new(-0.9433051, 0.6715302, -0.13446586));
        let axis = light_bounds(&Light::quad(Vec3::ZERO, edge_u, edge_v, Vec3::ONE, false)).axis.truncate();
        assert_ne!(axis.normalize(), axis, "the case needs an axis that normalising moves");
        for coincident in [false, true] {
            let lights: Vec<Light> = (0..16)
                .map(|i| {
                    let corner =
                        if coincident { Vec3::ZERO } else { Vec3::new((i % 4) as f32, (i / 4) as f32, 0.0) * 5.0 };
                    Light::quad(corner, edge_u, edge_v, Vec3::ONE, false)
                })
                .collect();
            check_structure(&LightBvh::build(&lights).unwrap(), &lights, MAX_BVH_DEPTH);
        }
    }

    #[test]
    fn lights_bvh_hard_cases() {
        let mut lights = random_lights(13, 40, 4.0);
        // A zero-power light is left out: pmf 0, never chosen; the rest still sum to 1.
        lights[7].radiance = Vec4::ZERO;
        let bvh = LightBvh::build(&lights).unwrap();
        check_structure(&bvh, &lights, MAX_BVH_DEPTH);
        check_pmfs(&bvh, &lights, 14, 200, 6.0);
        let sphere_index = lights.iter().position(|l| l.kind == light_kind::SPHERE).unwrap();
        let quad_index = lights.iter().position(|l| l.kind == light_kind::QUAD).unwrap();
        let q = &lights[quad_index];
        let on_quad = q.position.truncate() + 0.5 * (q.edge_u.truncate() + q.edge_v.truncate());
        let quad_normal = q.edge_u.truncate().cross(q.edge_v.truncate()).normalize();
        let outside_on_plane = q.position.truncate() + 3.0 * q.edge_u.truncate();
        for p in [lights[sphere_index].position.truncate(), on_quad, outside_on_plane] {
            for n in [Vec3::ZERO, quad_normal, -quad_normal, Vec3::X] {
                let pmfs: Vec<f32> = (0..40).map(|k| bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, n, k)).collect();
                assert!(pmfs.iter().all(|q| q.is_finite() && *q >= 0.0));
                assert_eq!(pmfs[7], 0.0);
                assert!((pmfs.iter().sum::<f32>() - 1.0).abs() < 1e-4, "{p} {n}");
                for u in [0.0, 0.25, 0.5, ONE_MINUS] {
                    let choice = select_bvh(&lights, bvh.nodes(), p, n, u);
                    assert!(choice.is_valid() && choice.index != 7);
                    assert_eq!(choice.pmf, pmfs[choice.index as usize]);
                }
            }
        }
    }

    const ONE_MINUS: f32 = raywave_kernels::hash::ONE_MINUS_EPSILON;

    /// An engine's own lights ([`Light::NO_MESH`]), each of a power `validate_light` accepts
    /// (3.1·10³⁸ W, within `f32`) but together past `f32::MAX`: the clusters' powers, summed in
    /// `f64`, are stored clamped to `f32::MAX` — every node's power finite (`as f32` had made them
    /// ∞, non-finite data handed to the kernels, whose importance clamp alone then kept the pmfs
    /// finite) — and the BVH still holds its children's bounds and selects with pmfs that sum to
    /// 1, positive for every light that reaches the point, the dim one too.
    #[test]
    fn lights_bvh_of_powers_past_f32_max_keeps_finite_node_powers() {
        // Quads, the lights the shade stage integrates: 1 m², two-sided, 2π·5·10³⁷ ≈ 3.1·10³⁸ W each.
        let quad = |corner: Vec3, radiance: f32| Light::quad(corner, Vec3::X, Vec3::Z, Vec3::splat(radiance), true);
        let mut lights: Vec<Light> = (0..10).map(|k| quad(Vec3::new(2.0 * k as f32, 0.0, 0.0), 5e37)).collect();
        lights.push(quad(Vec3::new(0.0, 8.0, 0.0), 1.0));
        assert!(lights.iter().all(|light| light.mesh == Light::NO_MESH));
        let total: f64 = lights.iter().map(|light| f64::from(light_bounds(light).phi)).sum();
        assert!(total > 5.0 * f64::from(f32::MAX), "{total}");
        let bvh = LightBvh::build(&lights).expect("each power fits f32");
        check_structure(&bvh, &lights, MAX_BVH_DEPTH);
        let powers: Vec<f32> = bvh.nodes().iter().map(|node| node.bounds.phi).collect();
        assert!(powers.iter().all(|phi| phi.is_finite() && *phi > 0.0), "{powers:?}");
        assert_eq!(powers[0], f32::MAX, "the root's power clamped");
        check_pmfs(&bvh, &lights, 41, 200, 10.0);
    }

    /// Ceiling points amid an array of small LEDs in the ceiling's plane, which light none of
    /// them, and a lamp below that lights them all: the BVH gives the lamp at least the linear
    /// scan's pmf (measured: 1 at every cluster's centre). Inside the LED clusters' spheres their
    /// importance had ignored where they face, and the lamp's pmf fell to 6.2·10⁻⁸ at the
    /// clusters' centres — below 2⁻²⁴ it is never drawn. At the same points with other normals,
    /// each light that reaches the point keeps a positive pmf: the cull is conservative.
    #[test]
    fn lights_bvh_culls_clusters_out_of_reach_inside_their_spheres() {
        // 20 × 20 LEDs 5 mm across, 0.25 m apart on the ceiling y = 3, emitting downwards
        // (x̂ × ẑ = −ŷ); a 0.2 m lamp at y = 1 emitting upwards (ẑ × x̂ = ŷ).
        let led = |k: usize| {
            let corner = Vec3::new((k % 20) as f32 * 0.25, 3.0, (k / 20) as f32 * 0.25);
            Light::quad(corner, 0.005 * Vec3::X, 0.005 * Vec3::Z, Vec3::splat(2000.0), false)
        };
        let mut lights: Vec<Light> = (0..400).map(led).collect();
        lights.push(Light::quad(Vec3::new(2.3, 1.0, 2.3), 0.2 * Vec3::Z, 0.2 * Vec3::X, Vec3::splat(10.0), false));
        let lamp = 400;
        let bvh = LightBvh::build(&lights).unwrap();
        let mut rng = CounterRng::new(31);
        let (mut least, mut least_of_scan, mut clusters) = (f32::INFINITY, f32::INFINITY, 0);
        for node in bvh.nodes().iter().filter(|node| node.is_leaf == 0) {
            let centre = (node.bounds.min.truncate() + node.bounds.max.truncate()) * 0.5;
            if centre.y < 2.99 {
                continue;
            }
            clusters += 1;
            // On the ceiling, a few ulp off it either side (hit points lie so; 1 ulp above had
            // brought the 6·10⁻⁸ back), and 5 cm below it, facing down.
            let ulps_off = |k: i32| Vec3 { y: f32::from_bits(centre.y.to_bits().wrapping_add_signed(k)), ..centre };
            for p in [-2, -1, 0, 1, 2, 4].map(ulps_off).into_iter().chain([centre - 0.05 * Vec3::Y]) {
                let pmf = bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, -Vec3::Y, lamp);
                let scan = importance_pmf(&lights, p, -Vec3::Y, lamp);
                least = least.min(pmf);
                least_of_scan = least_of_scan.min(pmf / scan);
            }
            for n in [Vec3::Y, rng.unit_vec3(), rng.unit_vec3()] {
                let p = centre + 0.01 * rng.unit_vec3();
                for (k, light) in lights.iter().enumerate() {
                    if contributes(light, &mut rng, p, n) {
                        let pmf = bvh_pmf(&lights, bvh.nodes(), bvh.trails(), p, n, k as u32);
                        assert!(pmf > 0.0, "light {k} reaches {p}, {n} but has pmf 0");
                    }
                }
            }
        }
        std::println!(
            "the lamp's least pmf at {clusters} LED clusters' centres: {least}, {least_of_scan} of the scan's"
        );
        assert!(clusters > 100 && least > 0.01, "{clusters} clusters, the lamp's pmf down to {least}");
        assert!(least_of_scan >= 1.0 - 1e-6, "the lamp's pmf down to {least_of_scan} of the scan's");
        check_pmfs(&bvh, &lights, 32, 200, 5.0);
    }

    #[test]
    fn lights_cone_union_contains_both_cones() {
        let mut rng = CounterRng::new(21);
        for _ in 0..2000 {
            let a = Cone { w: rng.unit_vec3().as_dvec3(), cos_theta: rng.range(-1.0, 1.0) as f64 };
            let b = Cone { w: rng.unit_vec3().as_dvec3(), cos_theta: rng.range(-1.0, 1.0) as f64 };
            let u = cone_union(a, b);
            let theta_u = u.cos_theta.acos();
            for c in [a, b] {
                let needed = angle_between(u.w, c.w) + c.cos_theta.acos();
                assert!(u.cos_theta == -1.0 || needed <= theta_u + 1e-9, "{a:?} ∪ {b:?} = {u:?}: {needed} > {theta_u}");
            }
        }
        // Parallel cones stay tight, but for the slack.
        let z = Cone { w: DVec3::Z, cos_theta: 1.0 };
        assert_eq!(cone_union(z, z).cos_theta, CONE_SLACK.cos());
        assert_eq!(round_down(1.0 - 1e-12), 1.0f32.next_down());
        assert_eq!(round_down(-2.0), -1.0);
    }

    #[test]
    fn lights_bvh_node_indices_fit_u32() {
        assert!(check_tree_size(1 << 31, 32).is_ok());
        let err = check_tree_size((1 << 31) + 1, 32).unwrap_err().to_string();
        assert!(
            err.contains("2147483649 lights of non-zero power do not fit") && err.contains("2147483648 at most"),
            "{err}"
        );
        assert!(check_tree_size(8, 3).is_ok() && check_tree_size(9, 3).is_err());
    }

    #[test]
    fn lights_bvh_threshold() {
        assert!(!wants_bvh(0) && !wants_bvh(8) && wants_bvh(9));
    }
}
