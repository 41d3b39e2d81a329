//! The plant: an industrial site in the spirit of the UNC Power Plant. Its natural objects are
//! what makes the Power Plant hard: floors and walls that are huge and simple, pipe runs that
//! are long and thin, a tall chimney, and machinery halls whose thousands of small parts are
//! one object spread over a whole hall. Clustering has to cut it into suitable objects.

use glam::DVec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::shapes;
use crate::error::SceneError;
use crate::load::LoadOptions;
use crate::object::{ObjectBuilder, Scene};

/// A hall is 40 m square; the site has as many as the triangle target asks for.
const HALL_SIZE: f64 = 40.0;
/// Triangles per hall at which the site grows another hall.
const TRIANGLES_PER_HALL: u64 = 400_000;

pub(super) fn generate(options: &LoadOptions) -> Result<Scene, SceneError> {
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let hall_count = (options.triangles / TRIANGLES_PER_HALL).clamp(1, 10_000) as usize;
    let columns = (hall_count as f64).sqrt().ceil() as usize;
    // Machinery takes 75 % of the triangles and pipes 25 %; buildings add a few thousand.
    let machinery_budget = options.triangles * 3 / 4 / hall_count as u64;
    let pipe_budget = options.triangles / 4;

    let progress = &options.progress;
    progress.set_length(hall_count as u64);
    progress.set_position(0);
    progress.set_message("generating plant");
    let mut builders = Vec::new();
    let mut hall_centers = Vec::new();
    for hall in 0..hall_count {
        let center = DVec3::new(
            (hall % columns) as f64 * HALL_SIZE,
            0.0,
            (hall / columns) as f64 * HALL_SIZE,
        );
        hall_centers.push(center);

        let mut floor = ObjectBuilder::new(format!("hall {hall} floor"));
        shapes::cuboid(
            &mut floor,
            center + DVec3::new(0.0, -0.25, 0.0),
            DVec3::new(HALL_SIZE * 0.5, 0.25, HALL_SIZE * 0.5),
            4,
            [150, 150, 145, 255],
        );
        builders.push(floor);

        let mut walls = ObjectBuilder::new(format!("hall {hall} walls"));
        let wall_color = [170, 160, 140, 255];
        for side in [-1.0, 1.0] {
            shapes::cuboid(
                &mut walls,
                center + DVec3::new(side * HALL_SIZE * 0.49, 6.0, 0.0),
                DVec3::new(0.2, 6.0, HALL_SIZE * 0.5),
                2,
                wall_color,
            );
        }
        builders.push(walls);

        builders.push(machinery(center, machinery_budget, &mut rng, hall));
        progress.inc(1);
    }

    let extent = columns as f64 * HALL_SIZE;
    let mut chimney = ObjectBuilder::new("chimney");
    let chimney_base = DVec3::new(-HALL_SIZE, 0.0, -HALL_SIZE);
    shapes::tube(
        &mut chimney,
        chimney_base,
        chimney_base + DVec3::Y * 80.0,
        4.0,
        2.5,
        64,
        40,
        true,
        [120, 90, 80, 255],
    );
    builders.push(chimney);

    // Pipe runs: long polylines across the site at a few heights, each one connected mesh.
    let pipe_count = (hall_count * 3).max(4);
    let per_pipe = pipe_budget / pipe_count as u64;
    for pipe in 0..pipe_count {
        let mut points = Vec::new();
        let height = rng.random_range(3.0..11.0);
        // Runs stay over the site: each leg turns, and the length of a leg is bounded by
        // the site's edge.
        let site_min = -0.5 * HALL_SIZE;
        let site_max = extent - 0.5 * HALL_SIZE;
        let mut at = DVec3::new(
            rng.random_range(site_min..site_max),
            height,
            rng.random_range(site_min..site_max),
        );
        points.push(at);
        for leg in 0..6 {
            let axis = if leg % 2 == 0 { 0 } else { 2 };
            let target = rng.random_range(site_min..site_max);
            if (target - at[axis]).abs() < 1.0 {
                continue;
            }
            at[axis] = target;
            points.push(at);
        }
        if points.len() < 2 {
            continue;
        }
        let radius = rng.random_range(0.15..0.6);
        let segments = 24u32;
        // Rings along each leg: the pipe's share of the budget over 2·segments per ring.
        let legs = (points.len() - 1) as u64;
        let rings = (per_pipe / (legs * 2 * segments as u64)).clamp(2, 100_000) as u32;
        let mut builder = ObjectBuilder::new(format!("pipe {pipe}"));
        let color = [
            60 + rng.random_range(0..120u8),
            80,
            140 + rng.random_range(0..80u8),
            255,
        ];
        let path: Vec<(DVec3, f64)> = points.iter().map(|p| (*p, radius)).collect();
        shapes::path_tube(&mut builder, &path, segments, rings, true, color);
        builders.push(builder);
    }
    let source = format!(
        "plant (target {} triangles, seed {})",
        options.triangles, options.seed
    );
    crate::load::finish_scene(source, builders)
}

/// A hall's machinery: machines (a housing box, tanks, valves, bolts), each many small
/// separate parts, together one object as big as the hall.
fn machinery(center: DVec3, budget: u64, rng: &mut ChaCha8Rng, hall: usize) -> ObjectBuilder {
    let mut builder = ObjectBuilder::new(format!("hall {hall} machinery"));
    // Finer tessellation when the budget is large keeps the part count moderate.
    let segments = if budget > 200_000 { 32 } else { 12 };
    while (builder.triangle_count() as u64) < budget {
        let machine = center
            + DVec3::new(
                rng.random_range(-0.42..0.42) * HALL_SIZE,
                0.0,
                rng.random_range(-0.42..0.42) * HALL_SIZE,
            );
        let color = [
            rng.random_range(80..230u8),
            rng.random_range(80..200u8),
            rng.random_range(40..120u8),
            255,
        ];
        let size = rng.random_range(1.0..2.5);
        shapes::cuboid(
            &mut builder,
            machine + DVec3::Y * size * 0.5,
            DVec3::new(size, size * 0.5, size * 0.7),
            3,
            color,
        );
        for _ in 0..rng.random_range(2..6) {
            let offset = DVec3::new(
                rng.random_range(-1.0..1.0) * size,
                0.0,
                rng.random_range(-1.0..1.0) * size,
            );
            let tank_height = rng.random_range(1.0..3.5);
            let base = machine + offset + DVec3::Y * size;
            shapes::tube(
                &mut builder,
                base,
                base + DVec3::Y * tank_height,
                0.4,
                0.4,
                segments,
                4,
                true,
                color,
            );
            shapes::sphere(
                &mut builder,
                base + DVec3::Y * tank_height,
                0.4,
                segments,
                color,
            );
            for bolt in 0..8 {
                let angle = std::f64::consts::TAU * bolt as f64 / 8.0;
                let bolt_at = base + DVec3::new(angle.cos() * 0.5, 0.05, angle.sin() * 0.5);
                shapes::tube(
                    &mut builder,
                    bolt_at,
                    bolt_at + DVec3::Y * 0.12,
                    0.04,
                    0.04,
                    6,
                    1,
                    true,
                    [90, 90, 90, 255],
                );
            }
            let valve_at = base + DVec3::new(0.5, tank_height * 0.5, 0.0);
            shapes::tube(
                &mut builder,
                valve_at,
                valve_at + DVec3::X * 0.6,
                0.08,
                0.08,
                segments / 2,
                2,
                true,
                [200, 40, 40, 255],
            );
        }
    }
    builder
}
