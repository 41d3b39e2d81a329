//! Phase II of Süß §4.5: how far the near zone reaches, and from that the largest cluster
//! side `sl_c` whose reliefboard never needs more than `p` pixels.

use glam::DVec3;

use crate::object::Object;

/// Triangles sampled (evenly, every k-th) to estimate the near-zone diameter.
const SAMPLE_TRIANGLES: u64 = 200_000;
/// Sample points tried as the centre of the near zone; the smallest ball wins.
const SEEDS: usize = 256;

/// The near-zone diameter `d_nz`: the diameter of the smallest ball, centred on a triangle,
/// that holds `t_nz` triangles. When the whole scene has at most `t_nz` triangles it is the
/// scene's diagonal: everything is near.
///
/// Estimated from up to 200,000 evenly spaced triangle centroids, each standing for the
/// triangles between it and the next, and 256 of them tried as centres: O(samples × seeds).
pub fn near_zone_diameter(objects: &[Object], t_nz: u64) -> f64 {
    let total: u64 = objects.iter().map(|o| o.triangles.len() as u64).sum();
    if total <= t_nz {
        let bounds = objects
            .iter()
            .fold(crate::geometry::Aabb::EMPTY, |b, o| b.union(o.bounds()));
        return bounds.diagonal();
    }
    let stride = total.div_ceil(SAMPLE_TRIANGLES).max(1);
    let mut samples: Vec<DVec3> = Vec::with_capacity((total / stride + 1) as usize);
    let mut global = 0u64;
    for object in objects {
        for triangle in &object.triangles {
            if global.is_multiple_of(stride) {
                let sum = triangle
                    .iter()
                    .map(|&v| object.world_position(v))
                    .sum::<DVec3>();
                samples.push(sum / 3.0);
            }
            global += 1;
        }
    }
    // How many samples stand for t_nz triangles (at least one: the seed itself).
    let k = (t_nz.div_ceil(stride) as usize).clamp(1, samples.len());
    let seed_stride = (samples.len() / SEEDS).max(1);
    let mut distances = vec![0.0f64; samples.len()];
    let mut smallest_radius_squared = f64::INFINITY;
    for seed in samples.iter().step_by(seed_stride) {
        for (distance, sample) in distances.iter_mut().zip(&samples) {
            *distance = seed.distance_squared(*sample);
        }
        let (_, kth, _) = distances.select_nth_unstable_by(k - 1, f64::total_cmp);
        smallest_radius_squared = smallest_radius_squared.min(*kth);
    }
    2.0 * smallest_radius_squared.sqrt()
}

/// The largest cluster side `sl_c` whose reliefboard, seen from the near zone's edge, covers
/// at most `map_size` pixels:
///
/// ```text
/// sl_c = 2 · p · d_nz · tan(fov_y / 2) / (√3 · r_y)
/// ```
///
/// A sphere of diameter `D` at distance `d` covers `D · r_y / (2 · d · tan(fov_y / 2))` pixels
/// of a view `r_y` pixels high (pixels are square, so the width adds nothing). A cluster's
/// board is made of its bounding sphere, whose diameter is at most `√3` times its longest side.
/// Setting the pixels to `p` at `d = d_nz` gives the formula; anything farther is smaller.
pub fn max_cluster_side(
    d_nz: f64,
    map_size: u32,
    resolution_height: u32,
    fov_y_degrees: f64,
) -> f64 {
    let half_fov = (fov_y_degrees.to_radians() * 0.5).tan();
    2.0 * map_size as f64 * d_nz * half_fov / (3f64.sqrt() * resolution_height as f64)
}
