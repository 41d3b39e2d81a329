//! Built-in procedural scenes, deterministic from a seed and sized by a triangle target.
//!
//! - [`forest`]: trees (and copies of user meshes) scattered over a terrain. Every tree is
//!   already a suitable object, like Süß's forest of bunnies and trees.
//! - [`plant`]: an industrial site in the spirit of the UNC Power Plant: long pipes, a
//!   chimney, floors, walls and dense machinery. Its natural objects are long, thin or huge,
//!   so it needs clustering.

mod forest;
mod plant;
pub mod shapes;

use crate::error::SceneError;
use crate::load::LoadOptions;
use crate::object::Scene;

/// The built-in scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuiltinScene {
    /// Trees over a terrain; already suitable.
    Forest,
    /// An industrial site; needs clustering.
    Plant,
}

/// Triangle targets outside this range are refused: below it a scene has too few triangles to
/// hold its parts, above it no 24 GiB machine holds it.
const TRIANGLE_TARGET_RANGE: std::ops::RangeInclusive<u64> = 1_000..=200_000_000;

impl BuiltinScene {
    /// The scene called `name`, if there is one.
    pub fn from_name(name: &str) -> Option<BuiltinScene> {
        match name {
            "forest" => Some(BuiltinScene::Forest),
            "plant" => Some(BuiltinScene::Plant),
            _ => None,
        }
    }

    /// Generates the scene with about `options.triangles` triangles.
    pub fn generate(self, options: &LoadOptions) -> Result<Scene, SceneError> {
        if !TRIANGLE_TARGET_RANGE.contains(&options.triangles) {
            return Err(SceneError::BadParameter(format!(
                "a built-in scene's triangle target must lie in {}..={}, got {}",
                TRIANGLE_TARGET_RANGE.start(),
                TRIANGLE_TARGET_RANGE.end(),
                options.triangles
            )));
        }
        match self {
            BuiltinScene::Forest => forest::generate(options),
            BuiltinScene::Plant => plant::generate(options),
        }
    }
}
