//! Phase I of Süß §4.5: weld duplicate vertices, drop duplicate faces, and split objects into
//! connected components (the base clusters), each with its AABB. Components too large for a
//! reliefboard but dense enough are cut further on a grid, so a huge mesh can still become
//! suitable objects.

use rustc_hash::{FxHashMap, FxHashSet};

use crate::geometry::Aabb;
use crate::object::Object;
use crate::union_find::UnionFind;

/// A group of triangles of one object.
#[derive(Debug, Clone)]
pub(crate) struct BaseCluster {
    pub bounds: Aabb,
    pub triangles: u64,
}

/// Phase I's result for a set of objects.
#[derive(Debug, Default)]
pub(crate) struct Components {
    pub clusters: Vec<BaseCluster>,
    /// Per object, per triangle: its base cluster, or `u32::MAX` for a dropped duplicate face.
    pub cluster_of_triangle: Vec<Vec<u32>>,
    pub duplicate_faces: u64,
    pub welded_vertices: u64,
    pub connected_components: u64,
    pub cut_components: u64,
}

pub(crate) const DROPPED: u32 = u32::MAX;

/// Runs Phase I on `objects`. A component whose longest side exceeds `max_side` is cut into
/// grid cells of side `max_side / 2` (by triangle centroid) when the cells then hold at least
/// `min_triangles` triangles on average; otherwise it stays whole (and too large).
pub(crate) fn split_into_components(
    objects: &[&Object],
    max_side: f64,
    min_triangles: u64,
) -> Components {
    let mut result = Components::default();
    for object in objects {
        let (welded, welded_count) = weld(object);
        result.welded_vertices += (object.positions.len() - welded_count) as u64;

        // Duplicate faces: the same three welded vertices, in any order.
        let mut seen = FxHashSet::default();
        seen.reserve(object.triangles.len());
        let mut keep = vec![true; object.triangles.len()];
        for (index, triangle) in object.triangles.iter().enumerate() {
            let mut key = triangle.map(|v| welded[v as usize]);
            key.sort_unstable();
            if !seen.insert(key) {
                keep[index] = false;
                result.duplicate_faces += 1;
            }
        }
        drop(seen);

        let mut sets = UnionFind::new(welded_count);
        for (triangle, _) in object.triangles.iter().zip(&keep).filter(|(_, k)| **k) {
            let [a, b, c] = triangle.map(|v| welded[v as usize]);
            sets.union(a, b);
            sets.union(a, c);
        }
        // Number the components and grow their boxes.
        let mut component_of_root: FxHashMap<u32, u32> = FxHashMap::default();
        let mut component_of_triangle = vec![DROPPED; object.triangles.len()];
        let mut bounds: Vec<Aabb> = Vec::new();
        let mut counts: Vec<u64> = Vec::new();
        for (index, triangle) in object.triangles.iter().enumerate() {
            if !keep[index] {
                continue;
            }
            let root = sets.find(welded[triangle[0] as usize]);
            let next = bounds.len() as u32;
            let component = *component_of_root.entry(root).or_insert(next);
            if component == next {
                bounds.push(Aabb::EMPTY);
                counts.push(0);
            }
            component_of_triangle[index] = component;
            counts[component as usize] += 1;
            for &v in triangle {
                bounds[component as usize] =
                    bounds[component as usize].including(object.world_position(v));
            }
        }
        result.connected_components += bounds.len() as u64;

        // Cut large, dense components on a grid; every other component is one base cluster.
        let first_cluster = result.clusters.len() as u32;
        let mut cells_of_component: FxHashMap<u32, FxHashMap<[i64; 3], u32>> = FxHashMap::default();
        for (component, (b, &triangles)) in bounds.iter().zip(&counts).enumerate() {
            if b.longest_side() > max_side
                && dense_enough_to_cut(triangles, b, max_side, min_triangles)
            {
                cells_of_component.insert(component as u32, FxHashMap::default());
            }
        }
        // Assign clusters: uncut components first, in order; cut ones get a cluster per cell.
        let mut clusters: Vec<BaseCluster> = Vec::new();
        let mut cluster_of_uncut = vec![DROPPED; bounds.len()];
        for (component, b) in bounds.iter().enumerate() {
            if !cells_of_component.contains_key(&(component as u32)) {
                cluster_of_uncut[component] = first_cluster + clusters.len() as u32;
                clusters.push(BaseCluster {
                    bounds: *b,
                    triangles: counts[component],
                });
            }
        }
        let cell_side = max_side * 0.5;
        for (index, triangle) in object.triangles.iter().enumerate() {
            let component = component_of_triangle[index];
            if component == DROPPED {
                continue;
            }
            let cluster = match cells_of_component.get_mut(&component) {
                None => cluster_of_uncut[component as usize],
                Some(cells) => {
                    let corners = triangle.map(|v| object.world_position(v));
                    let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
                    let key = (centroid / cell_side).floor().to_array().map(|c| c as i64);
                    let next = first_cluster + clusters.len() as u32;
                    let cluster = *cells.entry(key).or_insert(next);
                    if cluster == next {
                        clusters.push(BaseCluster {
                            bounds: Aabb::EMPTY,
                            triangles: 0,
                        });
                    }
                    let entry = &mut clusters[(cluster - first_cluster) as usize];
                    entry.triangles += 1;
                    for corner in corners {
                        entry.bounds = entry.bounds.including(corner);
                    }
                    cluster
                }
            };
            component_of_triangle[index] = cluster;
        }
        result.cut_components += cells_of_component.len() as u64;
        result.clusters.extend(clusters);
        result.cluster_of_triangle.push(component_of_triangle);
    }
    result
}

/// Whether `triangles` spread over `bounds` are dense enough that cutting them into cubes of
/// side `max_side` would give cubes with `min_triangles` triangles on average. The box
/// over-counts the volume of a sparse shape, so this errs towards leaving an object whole.
pub(crate) fn dense_enough_to_cut(
    triangles: u64,
    bounds: &Aabb,
    max_side: f64,
    min_triangles: u64,
) -> bool {
    if !(max_side > 0.0) {
        return false;
    }
    let cells: f64 = bounds
        .size()
        .to_array()
        .iter()
        .map(|s| (s / max_side).ceil().max(1.0))
        .product();
    triangles as f64 / cells >= min_triangles as f64
}

/// Maps every vertex to the first vertex at exactly the same position.
fn weld(object: &Object) -> (Vec<u32>, usize) {
    let mut first_at: FxHashMap<[u32; 3], u32> = FxHashMap::default();
    first_at.reserve(object.positions.len());
    let mut welded = Vec::with_capacity(object.positions.len());
    for position in &object.positions {
        // +0.0 folds -0.0 into 0.0, so both weld.
        let key = (*position + glam::Vec3::ZERO).to_array().map(f32::to_bits);
        let next = first_at.len() as u32;
        welded.push(*first_at.entry(key).or_insert(next));
    }
    let count = first_at.len();
    (welded, count)
}
