//! Why a dark component is no vehicle. The detector rejects most components of every frame, so
//! the reason is a small `Copy` value made on its path and formatted only where it is logged
//! (the trace of contact bands), never a string per rejection.

use std::fmt;

/// Why a component is no vehicle, with the measure that ruled it out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Rejection {
    /// It runs off the image's bottom: its contact line is not seen.
    OffTheBottom,
    /// Its contact line is above the horizon.
    AboveTheHorizon,
    /// Its contact is nearer than 1 m or beyond the detector's range (m ahead).
    ContactAt(f64),
    /// Nothing rises above its contact line against the background.
    NothingAbove,
    /// What rises above it is lower or higher than any vehicle (m).
    Height(f64),
    /// Its band is narrower or wider than any vehicle's rear, or side and rear (m).
    Width(f64),
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rejection::OffTheBottom => write!(f, "runs off the image bottom: the contact line is not seen"),
            Rejection::AboveTheHorizon => write!(f, "contact above the horizon"),
            Rejection::ContactAt(m) => write!(f, "contact at {m:.1} m"),
            Rejection::NothingAbove => write!(f, "nothing rises above the contact"),
            Rejection::Height(m) => write!(f, "height {m:.2} m"),
            Rejection::Width(m) => write!(f, "width {m:.2} m"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Rejection;

    #[test]
    fn a_rejection_is_said_with_its_measure() {
        assert_eq!(Rejection::ContactAt(212.34).to_string(), "contact at 212.3 m");
        assert_eq!(Rejection::Width(0.4).to_string(), "width 0.40 m");
        assert_eq!(std::mem::size_of::<Rejection>(), 16, "a tag and one f64, no heap");
    }
}
