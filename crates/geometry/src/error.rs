//! The one error type of the crate: an ill-posed question, never a failed computation.

/// Why a geometric query could not be posed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A semi-axis was zero, negative, infinite or NaN.
    #[error("semi-axis `{axis}` of {shape} is {value}; it must be finite and positive")]
    SemiAxis {
        /// Which shape (`"ellipse"`, `"A"`, `"B"`).
        shape: &'static str,
        /// `"a"` or `"b"`.
        axis: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A pose coordinate was infinite or NaN.
    #[error("pose of {shape} has non-finite {coordinate} = {value}")]
    Pose {
        /// Which shape (`"A"`, `"B"`).
        shape: &'static str,
        /// `"x"`, `"y"` or `"theta"`.
        coordinate: &'static str,
        /// The offending value.
        value: f64,
    },
}
