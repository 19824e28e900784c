//! [`Frame`], the rigid transform every part of the model speaks (poses, the tool, the base
//! frame), and its conversion to the file's [`PoseData`]. A leaf: it imports only the file
//! format.

use nalgebra::UnitQuaternion;

use super::file::PoseData;

/// A rigid transform (rotation matrix + translation, metres).
pub type Frame = nalgebra::IsometryMatrix3<f64>;

impl From<&Frame> for PoseData {
    /// The frame's translation (m) and rotation as a unit quaternion with w ≥ 0.
    fn from(f: &Frame) -> Self {
        let q = UnitQuaternion::from_rotation_matrix(&f.rotation);
        let s = if q.w < 0.0 { -1.0 } else { 1.0 };
        PoseData {
            translation: [f.translation.x, f.translation.y, f.translation.z],
            quaternion: [s * q.w, s * q.i, s * q.j, s * q.k],
        }
    }
}
