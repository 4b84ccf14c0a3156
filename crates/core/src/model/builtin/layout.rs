//! Landmarks and proportions of the built-in head, in metres (FLAME-like frame:
//! y up, +z forward out of the face, +x towards the subject's left).

use glam::{Vec2, Vec3};

/// Columns of the main surface grid (around the head).
pub const COLS: usize = 90;
/// Rows of the main surface grid (top pole excluded) from crown to neck cut.
pub const ROWS: usize = 52;

/// Column warp: share of linear term (the rest is cubic), packs columns at the face.
pub const COL_WARP_LINEAR: f32 = 0.6;
/// Row warp amplitude: rows are denser around the face band.
pub const ROW_WARP: f32 = 0.35;

/// Centre of the skull ellipsoid.
pub const SKULL_CENTER: Vec3 = Vec3::new(0.0, 0.008, -0.012);
/// Half-width of the skull (x).
pub const SKULL_RX: f32 = 0.076;
/// Half-height of the skull (y).
pub const SKULL_RY: f32 = 0.110;
/// Forward depth of the skull from its centre (z > 0 side).
pub const SKULL_RZ_FRONT: f32 = 0.094;
/// Backward depth of the skull from its centre (z < 0 side).
pub const SKULL_RZ_BACK: f32 = 0.100;
/// Polar angle (from the crown) reached by the skull part of the grid at `V_SKULL`.
pub const SKULL_THETA: f32 = 0.80 * std::f32::consts::PI;
/// Vertical parameter at which the skull angle reaches `SKULL_THETA`.
pub const V_SKULL: f32 = 0.78;
/// Vertical parameter range over which the skull blends into the neck tube.
pub const NECK_BLEND: (f32, f32) = (0.62, 0.86);
/// Neck tube: y at the top of the tube parameter range and at the cut.
pub const NECK_Y: (f32, f32) = (-0.060, -0.180);
/// Vertical parameter where the neck tube parameter starts.
pub const V_NECK: f32 = 0.62;
/// Neck half-width (x).
pub const NECK_RX: f32 = 0.054;
/// Neck forward and backward depth from its centre.
pub const NECK_RZ: (f32, f32) = (0.052, 0.058);
/// Neck tube centre (z).
pub const NECK_CZ: f32 = -0.018;

/// Centre of the left eyeball (the right one mirrors x).
pub const EYE_CENTER: Vec3 = Vec3::new(0.0315, 0.006, 0.060);
/// Eyeball radius.
pub const EYE_RADIUS: f32 = 0.0122;
/// Half-size (x, y) of the eye opening (palpebral fissure).
pub const EYE_OPENING: Vec2 = Vec2::new(0.0135, 0.0050);
/// Eye opening hole in grid cells (columns, rows).
pub const EYE_HOLE_CELLS: (usize, usize) = (8, 2);

/// Mouth line: y of the lips' meeting line.
pub const MOUTH_Y: f32 = -0.064;
/// Half-size (x, y) of the mouth slit at rest.
pub const MOUTH_OPENING: Vec2 = Vec2::new(0.0235, 0.0012);
/// Mouth slit in grid cells (columns, rows).
pub const MOUTH_HOLE_CELLS: (usize, usize) = (14, 1);

/// Centre of the left ear on the side of the head (the right one mirrors x).
pub const EAR_CENTER: Vec3 = Vec3::new(0.074, -0.006, -0.012);
/// Half-size of the ear: (height, width) in metres.
pub const EAR_SIZE: Vec2 = Vec2::new(0.031, 0.018);

/// Jaw hinge (the jaw joint position for the template).
pub const JAW_HINGE: Vec3 = Vec3::new(0.0, -0.022, -0.006);
/// Neck joint (head rotates about it).
pub const NECK_JOINT: Vec3 = Vec3::new(0.0, -0.080, -0.020);
/// Global joint, low on the neck.
pub const GLOBAL_JOINT: Vec3 = Vec3::new(0.0, -0.160, -0.018);

/// Which side of the face a bilateral part is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// Subject's left (+x).
    Left,
    /// Subject's right (-x).
    Right,
}

impl Side {
    /// +1 for left, -1 for right.
    pub fn sign(self) -> f32 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }

    /// Both sides, left first.
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// Mirrors a left-side landmark to this side.
    pub fn place(self, p: Vec3) -> Vec3 {
        Vec3::new(p.x * self.sign(), p.y, p.z)
    }
}
