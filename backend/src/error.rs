/// Why a reliefboard cannot be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The view direction is zero, NaN or infinite.
    #[error("view direction {0:?} must be finite and non-zero")]
    BadDirection([f64; 3]),
    /// The resolution is zero or above the configured maximum.
    #[error("resolution {size} must lie in 1..={max} pixels")]
    BadResolution {
        /// Requested side.
        size: u32,
        /// Largest allowed side.
        max: u32,
    },
    /// The object has no triangle or no extent.
    #[error("object {0:?} is empty or has no extent")]
    EmptyObject(String),
}
