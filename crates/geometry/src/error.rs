//! The one error type of the crate: an ill-posed question, never a failed computation.

/// Why a geometric query could not be posed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A semi-axis was outside [`crate::SEMI_AXIS_RANGE`] (zero, negative, infinite, NaN, or too small or
    /// large to compute with reliably).
    #[error("semi-axis `{axis}` of {shape} is {value:e}; it must be between 1e-6 and 1e6")]
    SemiAxis {
        /// Which shape (`"ellipse"`, `"A"`, `"B"`).
        shape: &'static str,
        /// `"a"` or `"b"`.
        axis: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A pose coordinate was infinite or NaN.
    #[error("pose of {shape} has non-finite {coordinate} = {value:?}")]
    Pose {
        /// Which shape (`"A"`, `"B"`).
        shape: &'static str,
        /// `"x"`, `"y"` or `"theta"`.
        coordinate: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A half-plane's point was not finite, or its normal not finite and non-zero.
    #[error(
        "half-plane through {point:?} with normal {normal:?}: the point must be finite and the normal finite and non-zero"
    )]
    InvalidHalfPlane {
        /// The point given.
        point: [f64; 2],
        /// The normal given.
        normal: [f64; 2],
    },
}
