//! The forest: procedural trees (trunk, branches, many leaf triangles) and copies of
//! user-given meshes, scattered over a gently rolling terrain.

use glam::DVec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::shapes;
use crate::error::SceneError;
use crate::load::{LoadOptions, load_file};
use crate::object::{Object, ObjectBuilder, Scene};

/// Süß's forest has 250 objects for 25 M triangles: about 100 k triangles an object.
const TRIANGLES_PER_OBJECT: u64 = 100_000;
/// Distance between neighbouring objects, in metres; a tree is 5-8 m tall and at most 7 m
/// wide, so with the default near-zone budget (sl_c about 10 m) every tree is suitable.
const SPACING: f64 = 14.0;
/// The terrain stays coarse (2 × 48² triangles): it is drawn as geometry anyway.
const TERRAIN_QUADS: u32 = 48;

pub(super) fn generate(options: &LoadOptions) -> Result<Scene, SceneError> {
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let copies: Vec<Object> = options
        .forest_meshes
        .iter()
        .map(|path| {
            let scene = load_file(
                path,
                &LoadOptions {
                    progress: crate::progress::Progress::hidden(),
                    ..options.clone()
                },
            )?;
            Ok(crate::object::merge_objects(
                &scene
                    .objects
                    .first()
                    .map(|o| o.name.clone())
                    .unwrap_or_default(),
                &scene.objects,
            ))
        })
        .collect::<Result<_, SceneError>>()?;

    let object_count = (options.triangles / TRIANGLES_PER_OBJECT).max(4) as usize;
    let per_object = (options.triangles / object_count as u64).max(200);
    let columns = (object_count as f64).sqrt().ceil() as usize;
    let half = columns as f64 * SPACING * 0.5;
    let height = |x: f64, z: f64| {
        2.0 * (x * 0.031).sin() * (z * 0.027).cos() + 1.2 * (x * 0.011 + z * 0.017).sin()
    };

    let progress = &options.progress;
    progress.set_length(object_count as u64);
    progress.set_position(0);
    progress.set_message("generating forest");
    let mut builders = Vec::with_capacity(object_count + 1);
    let mut terrain = ObjectBuilder::new("terrain");
    shapes::terrain(
        &mut terrain,
        half + SPACING,
        TERRAIN_QUADS,
        height,
        [92, 120, 60, 255],
    );
    builders.push(terrain);
    for index in 0..object_count {
        let (row, column) = (index / columns, index % columns);
        let jitter = DVec3::new(
            rng.random_range(-0.3..0.3),
            0.0,
            rng.random_range(-0.3..0.3),
        ) * SPACING;
        let mut base = DVec3::new(
            column as f64 * SPACING - half,
            0.0,
            row as f64 * SPACING - half,
        ) + jitter;
        base.y = height(base.x, base.z);
        // With user meshes, every other object is a copy of one of them.
        let builder = if !copies.is_empty() && index % 2 == 1 {
            let mesh = &copies[(index / 2) % copies.len()];
            copy_mesh(mesh, base, &mut rng, format!("{} {index}", mesh.name))
        } else {
            tree(base, per_object, &mut rng, format!("tree {index}"))
        };
        builders.push(builder);
        progress.inc(1);
    }
    let source = format!(
        "forest (target {} triangles, seed {})",
        options.triangles, options.seed
    );
    crate::load::finish_scene(source, builders)
}

/// One tree of about `budget` triangles: a trunk, two levels of branches and leaves at the
/// branch ends, which take whatever the wood leaves of the budget.
fn tree(base: DVec3, budget: u64, rng: &mut ChaCha8Rng, name: String) -> ObjectBuilder {
    let mut builder = ObjectBuilder::new(name);
    let height = rng.random_range(5.0..7.5);
    let bark = [95 + rng.random_range(0..20u8), 70, 45, 255];
    let segments = if budget > 20_000 { 12 } else { 6 };
    let top = base + DVec3::Y * height;
    shapes::tube(&mut builder, base, top, 0.35, 0.12, segments, 6, true, bark);

    let mut tips = Vec::new();
    let branch_count = rng.random_range(5..9);
    for b in 0..branch_count {
        let start = base + DVec3::Y * height * (0.35 + 0.6 * b as f64 / branch_count as f64);
        let angle = rng.random_range(0.0..std::f64::consts::TAU);
        let out = DVec3::new(angle.cos(), rng.random_range(0.3..0.8), angle.sin()).normalize();
        let length = rng.random_range(1.0..1.8) * (1.0 - 0.4 * b as f64 / branch_count as f64);
        let end = start + out * length;
        shapes::tube(
            &mut builder,
            start,
            end,
            0.1,
            0.04,
            segments / 2,
            3,
            false,
            bark,
        );
        for _ in 0..3 {
            let twig = (out
                + DVec3::new(
                    rng.random_range(-0.6..0.6),
                    rng.random_range(0.0..0.5),
                    rng.random_range(-0.6..0.6),
                ))
            .normalize();
            let twig_end = end + twig * length * 0.4;
            shapes::tube(&mut builder, end, twig_end, 0.04, 0.015, 3, 1, false, bark);
            tips.push(twig_end);
        }
    }
    tips.push(top);

    let leaf_budget = budget.saturating_sub(builder.triangle_count() as u64) / 2;
    let green = [
        40 + rng.random_range(0..40u8),
        110 + rng.random_range(0..50u8),
        40,
        255,
    ];
    builder.reserve(leaf_budget as usize * 4, leaf_budget as usize * 2);
    for leaf in 0..leaf_budget {
        let tip = tips[leaf as usize % tips.len()];
        let offset = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.8..1.0),
            rng.random_range(-1.0..1.0),
        ) * 0.8;
        let along = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(DVec3::X)
            * 0.09;
        let across = along.any_orthonormal_vector() * 0.04;
        let shade = rng.random_range(0..30u8);
        shapes::leaf(
            &mut builder,
            tip + offset,
            along,
            across,
            [green[0] + shade, green[1] + shade / 2, green[2], 255],
        );
    }
    builder
}

/// A copy of a user mesh standing at `base`, turned about the vertical and scaled to tree size.
fn copy_mesh(mesh: &Object, base: DVec3, rng: &mut ChaCha8Rng, name: String) -> ObjectBuilder {
    let bounds = mesh.bounds();
    let scale = rng.random_range(5.0..8.0) / bounds.size().max_element().max(1e-9);
    let rotation = glam::DQuat::from_rotation_y(rng.random_range(0.0..std::f64::consts::TAU));
    // Stand the mesh on the ground: its lowest point at `base`.
    let lift = (mesh.origin.y - bounds.min.y) * scale;
    let mut builder = ObjectBuilder::new(name);
    builder.reserve(mesh.positions.len(), mesh.triangles.len());
    for ((position, color), &seam) in mesh.positions.iter().zip(&mesh.colors).zip(&mesh.seams) {
        let v = builder.vertex(
            base + DVec3::Y * lift + rotation * (position.as_dvec3() * scale),
            *color,
        );
        if seam {
            builder.mark_seam(v);
        }
    }
    for &[a, b, c] in &mesh.triangles {
        builder.triangle(a, b, c);
    }
    builder
}
