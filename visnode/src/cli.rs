//! Command-line flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// The reliefboard visualization node.
#[derive(Debug, Parser)]
#[command(name = "visnode", version, about)]
pub struct Cli {
    /// What to do; without one, `inspect` on the default scene.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Load a scene, cut it into objects and report which become reliefboards.
    Inspect(InspectArgs),
}

/// Which scene to load and how to cut it: shared by every subcommand that reads a scene.
#[derive(Debug, Args, Clone)]
#[command(next_help_heading = "Scene")]
pub struct SceneArgs {
    /// A mesh file (.ply, .obj, .gltf, .glb, optionally .gz) or a built-in scene: forest, plant.
    #[arg(long, default_value = "forest")]
    pub scene: String,
    /// Triangle target of a built-in scene.
    #[arg(long, default_value_t = 1_000_000)]
    pub triangles: u64,
    /// Seed of a built-in scene.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A mesh copied into the built-in forest beside its trees (repeatable).
    #[arg(long = "forest-mesh")]
    pub forest_meshes: Vec<PathBuf>,
    /// Near-zone triangle budget t_nz.
    #[arg(long = "t-nz", default_value_t = scene::PrepareParams::DEFAULT_T_NZ)]
    pub t_nz: u64,
    /// Largest reliefboard map side p, in pixels.
    #[arg(long = "map-size", default_value_t = scene::PrepareParams::DEFAULT_MAP_SIZE)]
    pub map_size: u32,
    /// Display resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768", value_parser = parse_resolution)]
    pub resolution: [u32; 2],
    /// Vertical field of view in degrees.
    #[arg(long = "fov", default_value_t = scene::PrepareParams::DEFAULT_FOV_Y_DEGREES)]
    pub fov_y_degrees: f64,
    /// Objects with fewer triangles are too simple for a reliefboard.
    #[arg(long = "min-triangles", default_value_t = scene::PrepareParams::DEFAULT_MIN_TRIANGLES)]
    pub min_triangles: u64,
    /// Where clustering results are cached [default: $XDG_CACHE_HOME/reliefboard or ~/.cache/reliefboard].
    #[arg(long = "cache-dir")]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the clustering cache.
    #[arg(long = "no-cache")]
    pub no_cache: bool,
}

/// Flags of `visnode inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The scene.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write a top-down picture: suitable, too-large and too-simple objects in three colours.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

fn parse_resolution(text: &str) -> Result<[u32; 2], String> {
    let (width, height) = text
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, for example 1024x768")?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .map_err(|_| format!("{s:?} is not a whole number of pixels"))
    };
    let resolution = [parse(width)?, parse(height)?];
    if resolution.iter().any(|&r| r == 0 || r > 65_536) {
        return Err("each side must lie in 1..=65536 pixels".into());
    }
    Ok(resolution)
}
