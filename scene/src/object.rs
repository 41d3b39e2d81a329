use glam::{DVec3, Vec3};

use crate::geometry::Aabb;

/// A group of triangles drawn either as geometry or as one reliefboard.
///
/// Positions are `f32` relative to `origin`, the centre of the object's bounds, so precision
/// does not depend on where the object stands in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// A name for messages: the group, node or generator part it came from.
    pub name: String,
    /// World position of the local origin.
    pub origin: DVec3,
    /// Vertex positions relative to `origin`.
    pub positions: Vec<Vec3>,
    /// Unlit vertex colours, RGBA, sRGB-encoded; one per position.
    pub colors: Vec<[u8; 4]>,
    /// Counter-clockwise triangles indexing `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// One per position: whether the vertex lies on a cut between pieces of one larger mesh
    /// (`prepare` cuts a mesh too large for the near zone). A board grows past such edges so
    /// the boards of neighbouring pieces overlap instead of leaving cracks between them.
    pub seams: Vec<bool>,
}

impl Object {
    /// Bounds in world space.
    pub fn bounds(&self) -> Aabb {
        let local = Aabb::from_points(self.positions.iter().map(|p| p.as_dvec3()));
        if local.is_empty() {
            return local;
        }
        Aabb {
            min: local.min + self.origin,
            max: local.max + self.origin,
        }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// World position of vertex `index`.
    pub fn world_position(&self, index: u32) -> DVec3 {
        self.origin + self.positions[index as usize].as_dvec3()
    }
}

/// A scene: the objects as loaded or generated, before preprocessing.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// Where it came from: a file path or a built-in scene's name and parameters.
    pub source: String,
    /// The objects.
    pub objects: Vec<Object>,
    /// Zero-area triangles dropped while loading.
    pub degenerate_triangles_dropped: u64,
}

impl Scene {
    /// Total number of triangles.
    pub fn triangle_count(&self) -> u64 {
        self.objects.iter().map(|o| o.triangles.len() as u64).sum()
    }

    /// Bounds of every object.
    pub fn bounds(&self) -> Aabb {
        self.objects
            .iter()
            .fold(Aabb::EMPTY, |b, o| b.union(o.bounds()))
    }
}

/// All `objects` as one object called `name` (vertices in world space, recentred).
pub fn merge_objects(name: &str, objects: &[Object]) -> Object {
    let mut builder = ObjectBuilder::new(name);
    for object in objects {
        let first = builder.vertex_count() as u32;
        for (index, color) in object.colors.iter().enumerate() {
            let v = builder.vertex(object.world_position(index as u32), *color);
            if object.seams[index] {
                builder.mark_seam(v);
            }
        }
        for &[a, b, c] in &object.triangles {
            builder.triangle(first + a, first + b, first + c);
        }
    }
    builder.finish().0
}

/// Collects one object's vertices and triangles in world coordinates (`f64`), then
/// [`finish`](ObjectBuilder::finish)es it into an [`Object`] relative to its own centre.
///
/// The builder is where every loader and generator meets, so validation that is the same for
/// all of them lives here: zero-area triangles are dropped and counted.
#[derive(Debug, Default, Clone)]
pub struct ObjectBuilder {
    name: String,
    positions: Vec<DVec3>,
    colors: Vec<[u8; 4]>,
    triangles: Vec<[u32; 3]>,
    seams: Vec<bool>,
}

impl ObjectBuilder {
    /// An empty object called `name`.
    pub fn new(name: impl Into<String>) -> ObjectBuilder {
        ObjectBuilder {
            name: name.into(),
            ..Default::default()
        }
    }

    /// Adds a vertex and returns its index. The caller guarantees a finite position.
    pub fn vertex(&mut self, position: DVec3, color: [u8; 4]) -> u32 {
        debug_assert!(position.is_finite());
        self.positions.push(position);
        self.colors.push(color);
        self.seams.push(false);
        (self.positions.len() - 1) as u32
    }

    /// Marks vertex `v` (already added) as lying on a cut ([`Object::seams`]).
    pub fn mark_seam(&mut self, v: u32) {
        self.seams[v as usize] = true;
    }

    /// Adds a triangle of vertices already added. The caller guarantees the indices exist.
    pub fn triangle(&mut self, a: u32, b: u32, c: u32) {
        debug_assert!((a.max(b).max(c) as usize) < self.positions.len());
        self.triangles.push([a, b, c]);
    }

    /// Number of vertices so far.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles so far.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Reserves room for more vertices and triangles.
    pub fn reserve(&mut self, vertices: usize, triangles: usize) {
        self.positions.reserve(vertices);
        self.colors.reserve(vertices);
        self.seams.reserve(vertices);
        self.triangles.reserve(triangles);
    }

    /// Recentres the object on its bounds and drops zero-area triangles.
    ///
    /// Returns the object and the number of triangles dropped. A triangle counts as zero-area
    /// when twice its area is below `1e-12` times its longest edge squared: it has no
    /// direction, so it has no normal and covers no pixel.
    pub fn finish(self) -> (Object, u64) {
        let ObjectBuilder {
            name,
            positions,
            mut colors,
            mut triangles,
            mut seams,
        } = self;
        let before = triangles.len();
        triangles.retain(|&[a, b, c]| {
            let (pa, pb, pc) = (
                positions[a as usize],
                positions[b as usize],
                positions[c as usize],
            );
            !is_degenerate(pa, pb, pc)
        });
        let dropped = (before - triangles.len()) as u64;
        // The object is kept for the scene's life: no room left over from pushing.
        triangles.shrink_to_fit();
        colors.shrink_to_fit();
        seams.shrink_to_fit();
        let bounds = Aabb::from_points(positions.iter().copied());
        let origin = if bounds.is_empty() {
            DVec3::ZERO
        } else {
            bounds.center()
        };
        let positions = positions.iter().map(|p| (*p - origin).as_vec3()).collect();
        (
            Object {
                name,
                origin,
                positions,
                colors,
                triangles,
                seams,
            },
            dropped,
        )
    }
}

/// Whether a triangle has (next to) no area; computed relative to `a` so far-away triangles
/// keep their precision.
pub(crate) fn is_degenerate(a: DVec3, b: DVec3, c: DVec3) -> bool {
    let (ab, ac, bc) = (b - a, c - a, c - b);
    let longest_squared = ab
        .length_squared()
        .max(ac.length_squared())
        .max(bc.length_squared());
    let twice_area = ab.cross(ac).length();
    !(twice_area > 1e-12 * longest_squared) || longest_squared == 0.0
}
