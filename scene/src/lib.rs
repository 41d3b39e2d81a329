//! The scene model shared by every reliefboard crate: objects made of triangles, the loaders
//! that read them from PLY, OBJ and glTF files, the built-in procedural scenes, and the
//! preprocessing that cuts a scene into objects suitable for reliefboards (Süß 2011, §4.5).
//!
//! Start reading at [`Scene`] and [`Object`], then [`load_scene`] (file or built-in name in,
//! [`Scene`] out) and [`prepare()`] (a [`Scene`] in, a [`PreparedScene`] with every object
//! classified as suitable, too large or too simple out).
//!
//! **Architecture invariant:** this crate knows nothing of gRPC, wgpu, tokio or the balancer.
//! It depends on no sibling crate, so every other crate can depend on it.
//!
//! Coordinates: world positions are `f64`; an object's vertices are `f32` relative to the
//! object's own `origin` (the centre of its bounds), so a millimetre-sized object ten thousand
//! kilometres from the world origin keeps its shape.
#![warn(missing_docs)]

mod builtin;
mod error;
mod geometry;
mod load;
mod object;
mod prepare;
mod progress;
mod save;
mod union_find;

pub use builtin::{BuiltinScene, shapes};
pub use error::{Problem, SceneError};
pub use geometry::{Aabb, view_axes};
pub use load::{LoadLimits, LoadOptions, load_bytes, load_file, load_scene};
pub use object::{Object, ObjectBuilder, Scene, merge_objects};
pub use prepare::{
    ClusterOutcome, DenseCut, ObjectClass, PhaseReport, PrepareParams, PreparedScene, Summary,
    classify, cluster_boxes, connected_components, max_cluster_side, near_zone_diameter, prepare,
};
pub use save::{write_glb, write_obj, write_ply};
pub use union_find::UnionFind;

pub use progress::{Progress, ProgressRead, ProgressSink};
