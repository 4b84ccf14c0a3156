//! Frame pacing: the render resolution follows the time budget while the view
//! moves (playing, orbiting, editing) and returns to full size when it settles.

/// Frame budget while moving: 25 FPS, the rate motions are captured at.
pub const FRAME_BUDGET_MS: f64 = 40.0;
/// Smallest resolution scale used while moving.
pub const MIN_SCALE: f64 = 0.25;

/// The next resolution scale after a frame at `scale` took `spent_ms` (render +
/// encode): aims for the budget (cost ∝ pixels ∝ scale²), smoothed.
pub fn next_scale(scale: f64, spent_ms: f64) -> f64 {
    if spent_ms <= 0.0 || !spent_ms.is_finite() {
        return scale;
    }
    let target = (scale * (FRAME_BUDGET_MS / spent_ms).sqrt()).clamp(MIN_SCALE, 1.0);
    (0.7 * scale + 0.3 * target).clamp(MIN_SCALE, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_shrinks_when_slow_and_grows_when_fast() {
        assert!(next_scale(1.0, 160.0) < 1.0);
        assert!(next_scale(0.5, 5.0) > 0.5);
        assert_eq!(next_scale(1.0, 10.0), 1.0);
        let mut s = 1.0;
        for _ in 0..50 {
            s = next_scale(s, 160.0 * s * s); // cost ∝ pixels
        }
        assert!((s - 0.5).abs() < 0.02, "converges to the budget: {s}");
    }
}
