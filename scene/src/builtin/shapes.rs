//! Tessellated primitives the generators build from. Each adds vertices and counter-clockwise
//! triangles to an [`ObjectBuilder`] in world coordinates.

use std::f64::consts::TAU;

use glam::{DQuat, DVec3};

use crate::object::ObjectBuilder;

/// A tube from `a` to `b` whose radius goes from `radius_a` to `radius_b`, with `segments`
/// around and `rings` along, optionally closed by caps.
#[allow(clippy::too_many_arguments)]
pub fn tube(
    builder: &mut ObjectBuilder,
    a: DVec3,
    b: DVec3,
    radius_a: f64,
    radius_b: f64,
    segments: u32,
    rings: u32,
    caps: bool,
    color: [u8; 4],
) {
    path_tube(
        builder,
        &[(a, radius_a), (b, radius_b)],
        segments,
        rings,
        caps,
        color,
    );
}

/// A connected tube along a polyline of (point, radius), `rings` rings per leg: one
/// connected component, like a pipe run.
pub fn path_tube(
    builder: &mut ObjectBuilder,
    points: &[(DVec3, f64)],
    segments: u32,
    rings: u32,
    caps: bool,
    color: [u8; 4],
) {
    let segments = segments.max(3);
    let rings = rings.max(1);
    let mut ring_starts = Vec::new();
    // The rings' frame: glam's for the first leg, then carried around each bend by the
    // rotation that turns one leg into the next, so the rings never twist at a joint.
    let mut frame: Option<(DVec3, DVec3, DVec3)> = None;
    for (leg, pair) in points.windows(2).enumerate() {
        let ((a, radius_a), (b, radius_b)) = (pair[0], pair[1]);
        let axis = (b - a).normalize();
        let (u, v) = match frame {
            None => axis.any_orthonormal_pair(),
            Some((previous, u, v)) => {
                let turn = DQuat::from_rotation_arc(previous, axis);
                (turn * u, turn * v)
            }
        };
        frame = Some((axis, u, v));
        let first_ring = if leg == 0 { 0 } else { 1 };
        for ring in first_ring..=rings {
            let t = ring as f64 / rings as f64;
            let center = a.lerp(b, t);
            let radius = radius_a + (radius_b - radius_a) * t;
            ring_starts.push(builder.vertex_count() as u32);
            for s in 0..segments {
                let angle = TAU * s as f64 / segments as f64;
                builder.vertex(center + (u * angle.cos() + v * angle.sin()) * radius, color);
            }
        }
    }
    for pair in ring_starts.windows(2) {
        for s in 0..segments {
            let (s0, s1) = (s, (s + 1) % segments);
            let (p0, p1, q0, q1) = (pair[0] + s0, pair[0] + s1, pair[1] + s0, pair[1] + s1);
            builder.triangle(p0, p1, q1);
            builder.triangle(p0, q1, q0);
        }
    }
    if caps {
        let (first, last) = (points[0], points[points.len() - 1]);
        cap(builder, ring_starts[0], segments, first.0, color, true);
        cap(
            builder,
            *ring_starts.last().unwrap_or(&0),
            segments,
            last.0,
            color,
            false,
        );
    }
}

fn cap(
    builder: &mut ObjectBuilder,
    ring: u32,
    segments: u32,
    center: DVec3,
    color: [u8; 4],
    start: bool,
) {
    let middle = builder.vertex(center, color);
    for s in 0..segments {
        let (a, b) = (ring + s, ring + (s + 1) % segments);
        if start {
            builder.triangle(middle, b, a)
        } else {
            builder.triangle(middle, a, b)
        }
    }
}

/// A box with `center`, `half` extents and `subdivisions` quads along each edge.
pub fn cuboid(
    builder: &mut ObjectBuilder,
    center: DVec3,
    half: DVec3,
    subdivisions: u32,
    color: [u8; 4],
) {
    let n = subdivisions.max(1);
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let normal = DVec3::AXES[axis] * sign;
            let (u, v) = (DVec3::AXES[(axis + 1) % 3], DVec3::AXES[(axis + 2) % 3]);
            let (u, v) = if sign > 0.0 { (u, v) } else { (v, u) };
            let first = builder.vertex_count() as u32;
            for i in 0..=n {
                for j in 0..=n {
                    let (s, t) = (
                        i as f64 / n as f64 * 2.0 - 1.0,
                        j as f64 / n as f64 * 2.0 - 1.0,
                    );
                    let local = normal + u * s + v * t;
                    builder.vertex(center + local * half, color);
                }
            }
            for i in 0..n {
                for j in 0..n {
                    let at = |i: u32, j: u32| first + i * (n + 1) + j;
                    builder.triangle(at(i, j), at(i + 1, j), at(i + 1, j + 1));
                    builder.triangle(at(i, j), at(i + 1, j + 1), at(i, j + 1));
                }
            }
        }
    }
}

/// A UV sphere with a single vertex at each pole.
pub fn sphere(
    builder: &mut ObjectBuilder,
    center: DVec3,
    radius: f64,
    segments: u32,
    color: [u8; 4],
) {
    let segments = segments.max(4);
    let rings = (segments / 2).max(2);
    let north = builder.vertex(center + DVec3::Y * radius, color);
    let first = builder.vertex_count() as u32;
    for ring in 1..rings {
        let phi = std::f64::consts::PI * ring as f64 / rings as f64;
        for s in 0..segments {
            let theta = TAU * s as f64 / segments as f64;
            let direction = DVec3::new(phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin());
            builder.vertex(center + direction * radius, color);
        }
    }
    let south = builder.vertex(center - DVec3::Y * radius, color);
    let at = |r: u32, s: u32| first + r * segments + s % segments;
    for s in 0..segments {
        builder.triangle(north, at(0, s + 1), at(0, s));
        builder.triangle(south, at(rings - 2, s), at(rings - 2, s + 1));
    }
    for ring in 0..rings - 2 {
        for s in 0..segments {
            builder.triangle(at(ring, s), at(ring, s + 1), at(ring + 1, s + 1));
            builder.triangle(at(ring, s), at(ring + 1, s + 1), at(ring + 1, s));
        }
    }
}

/// A two-triangle leaf: a rhombus at `center` spanning `along` (tip direction) and `across`.
pub fn leaf(
    builder: &mut ObjectBuilder,
    center: DVec3,
    along: DVec3,
    across: DVec3,
    color: [u8; 4],
) {
    let a = builder.vertex(center - along, color);
    let b = builder.vertex(center - across, color);
    let c = builder.vertex(center + along, color);
    let d = builder.vertex(center + across, color);
    builder.triangle(a, b, c);
    builder.triangle(a, c, d);
}

/// A height field over the square `[-half, half]²` in x and z with `n × n` quads.
pub fn terrain(
    builder: &mut ObjectBuilder,
    half: f64,
    n: u32,
    height: impl Fn(f64, f64) -> f64,
    color: [u8; 4],
) {
    let first = builder.vertex_count() as u32;
    for i in 0..=n {
        for j in 0..=n {
            let x = -half + 2.0 * half * i as f64 / n as f64;
            let z = -half + 2.0 * half * j as f64 / n as f64;
            builder.vertex(DVec3::new(x, height(x, z), z), color);
        }
    }
    for i in 0..n {
        for j in 0..n {
            let at = |i: u32, j: u32| first + i * (n + 1) + j;
            builder.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
            builder.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Around every bend of a pipe, each ring vertex turns by at most the bend's angle: the
    /// frame is carried, not chosen afresh per leg (which could twist the quads between rings).
    #[test]
    fn pipe_rings_turn_with_the_bend_and_never_twist() {
        let points = [
            DVec3::ZERO,
            DVec3::new(1.0, 0.3, 0.2),
            DVec3::new(1.2, 1.0, 0.9),
            DVec3::new(0.3, 1.5, 1.8),
            DVec3::new(0.3, 1.5, -1.0),
        ];
        let segments = 8;
        let mut builder = ObjectBuilder::new("pipe");
        let path: Vec<(DVec3, f64)> = points.iter().map(|&p| (p, 0.1)).collect();
        path_tube(&mut builder, &path, segments, 1, false, [255; 4]);
        let (object, _) = builder.finish();
        let ring = |k: usize| -> Vec<DVec3> {
            (0..segments as usize)
                .map(|s| object.world_position((k * segments as usize + s) as u32))
                .collect()
        };
        // One ring per point: ring 0 and 1 belong to the first leg, ring k + 1 to leg k.
        // Positions are stored as f32, hence the tolerance.
        for k in 1..points.len() - 1 {
            let (at, after) = (ring(k), ring(k + 1));
            let incoming = (points[k] - points[k - 1]).normalize();
            let outgoing = (points[k + 1] - points[k]).normalize();
            let bend = incoming.dot(outgoing);
            for s in 0..segments as usize {
                let here = (at[s] - points[k]).normalize();
                let next = (after[s] - points[k + 1]).normalize();
                assert!(
                    here.dot(incoming).abs() < 1e-5,
                    "ring {k} is square to its leg"
                );
                assert!(next.dot(outgoing).abs() < 1e-5, "ring {} too", k + 1);
                assert!(here.dot(next) >= bend - 1e-5, "ring {k} vertex {s} twisted");
            }
        }
    }
}
