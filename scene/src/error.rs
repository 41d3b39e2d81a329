use std::fmt;

/// Everything that can go wrong while loading, generating or preparing a scene.
///
/// Every variant names the file (or scene) and, where there is one, the element at fault, so
/// the message alone tells a user what to fix.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The file was read but its content is invalid.
    #[error("{path}: {location}: {problem}")]
    Invalid {
        /// The file.
        path: String,
        /// Where in the file: "line 12", "vertex 17", "face 3", "accessor 2"...
        location: String,
        /// What is wrong there.
        problem: Problem,
    },
    /// The file's extension names no format we read.
    #[error(
        "{path}: unsupported file type (expected .ply, .obj, .gltf or .glb, optionally gzipped)"
    )]
    UnsupportedFormat {
        /// The file.
        path: String,
    },
    /// After validation nothing drawable is left.
    #[error("{source_name}: the scene is empty: {why}")]
    Empty {
        /// The file or built-in scene.
        source_name: String,
        /// Why nothing is left.
        why: String,
    },
    /// A name that is neither a file nor a built-in scene.
    #[error(
        "{0:?} is neither an existing file nor a built-in scene (built-in scenes: forest, plant); \
         the benchmark meshes (the Stanford dragon) are not in the repository: testdata/README.md \
         says where to get them"
    )]
    UnknownScene(String),
    /// A parameter outside its valid range.
    #[error("invalid parameter: {0}")]
    BadParameter(String),
}

/// What is wrong with an element of a mesh file.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Problem {
    /// A coordinate that is NaN or infinite.
    NonFiniteCoordinate(f64),
    /// A face refers to a vertex that does not exist.
    IndexOutOfRange {
        /// The index as written in the file.
        index: i64,
        /// How many vertices there are.
        vertex_count: usize,
    },
    /// A face with fewer than three vertices.
    TooFewVertices(usize),
    /// The file ends before the data its header promises.
    Truncated,
    /// Anything else that does not follow the format.
    Malformed(String),
    /// The file would cause more work than a [`crate::LoadLimits`] allows.
    TooLarge(String),
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::NonFiniteCoordinate(value) => write!(f, "coordinate {value} is not finite"),
            Problem::IndexOutOfRange {
                index,
                vertex_count,
            } => write!(
                f,
                "vertex index {index} is out of range (the file has {vertex_count} vertices)"
            ),
            Problem::TooFewVertices(count) => {
                write!(f, "a face needs at least 3 vertices, this one has {count}")
            }
            Problem::Truncated => write!(f, "the file ends early (truncated)"),
            Problem::Malformed(message) => write!(f, "{message}"),
            Problem::TooLarge(message) => write!(f, "too large: {message}"),
        }
    }
}
