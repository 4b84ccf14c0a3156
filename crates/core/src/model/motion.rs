//! Motions: per-frame expression coefficients and joint poses, and the built-in
//! sequences (talk, smile, blink, head turn) generated deterministically.

use std::f32::consts::TAU;

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::head::{Joint, Pose};

/// A driving sequence: expression coefficients and a pose for every frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    /// Name used on the command line and in recipes.
    pub name: String,
    /// Playback rate.
    pub fps: f32,
    /// Expression coefficients per frame (all rows the same length).
    pub expression: Vec<Vec<f32>>,
    /// Joint poses per frame.
    pub poses: Vec<Pose>,
    /// Per-frame vertex offsets, added to the unposed mesh with the
    /// expression, before skinning (VHAP's `dynamic_offset`, what FLAME's
    /// parameters could not fit in a tracked frame): one row per frame, or
    /// none at all.
    pub offsets: Vec<Vec<Vec3>>,
}

impl Motion {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.poses.len()
    }

    /// Expression and pose of a frame; the sequence loops.
    pub fn frame(&self, index: usize) -> (&[f32], &Pose) {
        let i = index % self.frames().max(1);
        (&self.expression[i], &self.poses[i])
    }

    /// The vertex offsets of a frame, when the motion has them; the
    /// sequence loops as in [`Motion::frame`].
    pub fn frame_offset(&self, index: usize) -> Option<&[Vec3]> {
        let rows = self.offsets.len();
        (rows > 0).then(|| self.offsets[index % rows].as_slice())
    }

    /// A one-frame motion at rest.
    pub fn rest(expression_count: usize) -> Motion {
        Motion {
            name: "rest".into(),
            fps: 25.0,
            expression: vec![vec![0.0; expression_count]],
            poses: vec![Pose::REST],
            offsets: Vec::new(),
        }
    }
}

/// Frames of each built-in motion (5 s at 25 FPS).
pub const BUILTIN_FRAMES: usize = 125;

/// Names of the built-in motions, in order.
pub const BUILTIN_MOTIONS: [&str; 4] = ["talk", "smile", "blink", "head_turn"];

/// Looks up expression components by name so motions stay valid if the basis grows.
struct Channels<'a> {
    names: &'a [String],
}

impl Channels<'_> {
    fn set(&self, row: &mut [f32], name: &str, value: f32) {
        if let Some(k) = self.names.iter().position(|n| n == name) {
            row[k] = value;
        }
    }
}

/// A smooth blink pulse centred at `t0` (frames), width ~5 frames.
fn blink_pulse(frame: f32, t0: f32) -> f32 {
    (-((frame - t0) / 2.2).powi(2)).exp()
}

/// Builds one built-in motion by name, for a model with the given expression names.
/// `variation` shifts phases and amplitudes so different sources move differently.
pub fn builtin_motion(name: &str, expression_names: &[String], variation: u64) -> Option<Motion> {
    let channels = Channels {
        names: expression_names,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0x6d6f_7469_6f6e ^ variation);
    let amp: f32 = 1.0 + 0.2 * (rng.random::<f32>() - 0.5);
    let phase: f32 = rng.random::<f32>() * TAU;
    let mut expression = Vec::with_capacity(BUILTIN_FRAMES);
    let mut poses = Vec::with_capacity(BUILTIN_FRAMES);
    // Syllable timings for speech: random but fixed by the seed.
    let syllables: Vec<(f32, f32)> = (0..40)
        .map(|i| {
            (
                i as f32 * 3.2 + rng.random::<f32>() * 1.5,
                0.5 + rng.random::<f32>() * 0.5,
            )
        })
        .collect();
    for f in 0..BUILTIN_FRAMES {
        let t = f as f32;
        let mut row = vec![0.0; expression_names.len()];
        let mut pose = Pose::REST;
        match name {
            "talk" => {
                let open: f32 = syllables
                    .iter()
                    .map(|&(t0, a)| a * (-((t - t0) / 1.1).powi(2)).exp())
                    .sum::<f32>()
                    .min(1.0);
                pose.joints[Joint::Jaw as usize] = Vec3::new(0.16 * amp * open, 0.0, 0.0);
                channels.set(&mut row, "jaw_open", 0.3 * open);
                channels.set(&mut row, "pucker", 0.5 * (0.21 * t + phase).sin().max(0.0));
                channels.set(&mut row, "smile", 0.3 + 0.2 * (0.05 * t + phase).sin());
                channels.set(&mut row, "brow_raise", 0.4 * (0.11 * t).sin().max(0.0));
                let blink = blink_pulse(t, 40.0) + blink_pulse(t, 98.0);
                channels.set(&mut row, "blink_left", blink);
                channels.set(&mut row, "blink_right", blink);
                pose.joints[Joint::Neck as usize] = Vec3::new(
                    0.05 * (0.07 * t + phase).sin(),
                    0.08 * (0.031 * t).sin(),
                    0.0,
                );
            }
            "smile" => {
                let s = ((t / BUILTIN_FRAMES as f32) * TAU).sin().max(0.0).powf(0.7);
                channels.set(&mut row, "smile", 1.6 * amp * s);
                channels.set(&mut row, "squint", 0.6 * s);
                channels.set(&mut row, "cheek_puff", 0.2 * s);
                pose.joints[Joint::Jaw as usize] = Vec3::new(0.05 * s, 0.0, 0.0);
                let blink = blink_pulse(t, 70.0);
                channels.set(&mut row, "blink_left", blink);
                channels.set(&mut row, "blink_right", blink);
                pose.joints[Joint::Neck as usize] = Vec3::new(-0.06 * s, 0.05 * s, 0.0);
            }
            "blink" => {
                let period = 31.0 + 6.0 * amp;
                let left = (0..5)
                    .map(|k| blink_pulse(t, 12.0 + k as f32 * period))
                    .sum::<f32>();
                // The last blink is a wink of the left eye only.
                let right = (0..4)
                    .map(|k| blink_pulse(t, 12.0 + k as f32 * period))
                    .sum::<f32>();
                channels.set(&mut row, "blink_left", left.min(1.0));
                channels.set(&mut row, "blink_right", right.min(1.0));
                channels.set(
                    &mut row,
                    "brow_raise",
                    0.3 * (0.09 * t + phase).sin().max(0.0),
                );
                let gaze = Vec3::new(
                    0.08 * (0.05 * t).sin(),
                    0.2 * (0.043 * t + phase).sin(),
                    0.0,
                );
                pose.joints[Joint::LeftEye as usize] = gaze;
                pose.joints[Joint::RightEye as usize] = gaze;
            }
            "head_turn" => {
                let yaw = 0.55 * amp * (t / BUILTIN_FRAMES as f32 * TAU).sin();
                let pitch = 0.12 * (2.0 * t / BUILTIN_FRAMES as f32 * TAU + phase).sin();
                pose.joints[Joint::Neck as usize] = Vec3::new(pitch, 0.6 * yaw, 0.0);
                pose.joints[Joint::Global as usize] = Vec3::new(0.0, 0.4 * yaw, 0.0);
                // Eyes lead the turn a little.
                let gaze = Vec3::new(
                    0.0,
                    0.25 * (t / BUILTIN_FRAMES as f32 * TAU + 0.4).sin(),
                    0.0,
                );
                pose.joints[Joint::LeftEye as usize] = gaze;
                pose.joints[Joint::RightEye as usize] = gaze;
                channels.set(&mut row, "smile", 0.25);
            }
            _ => return None,
        }
        expression.push(row);
        poses.push(pose);
    }
    Some(Motion {
        name: name.to_string(),
        fps: 25.0,
        expression,
        poses,
        offsets: Vec::new(),
    })
}

/// All built-in motions (without variation).
pub fn builtin_motions(expression_names: &[String]) -> Vec<Motion> {
    BUILTIN_MOTIONS
        .iter()
        .filter_map(|n| builtin_motion(n, expression_names, 0))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        ["jaw_open", "smile", "blink_left", "blink_right"]
            .map(String::from)
            .to_vec()
    }

    #[test]
    fn builtin_motions_are_long_enough_and_finite() {
        let motions = builtin_motions(&names());
        assert_eq!(motions.len(), 4);
        for m in &motions {
            assert!(m.frames() >= 110, "{} has {} frames", m.name, m.frames());
            assert!(m.expression.iter().flatten().all(|x| x.is_finite()));
            assert!(m
                .poses
                .iter()
                .all(|p| p.joints.iter().all(|j| j.is_finite())));
        }
    }

    #[test]
    fn frames_loop() {
        let m = builtin_motion("talk", &names(), 0).unwrap();
        assert_eq!(m.frame(3).1, m.frame(3 + m.frames()).1);
    }

    #[test]
    fn unknown_motion_is_none() {
        assert!(builtin_motion("dance", &names(), 0).is_none());
    }
}
