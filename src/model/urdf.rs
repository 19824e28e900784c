//! A URDF of the model, so RViz, MoveIt, Foxglove and a physics engine see the arm the
//! calibration found: its kinematics exactly, its bodies as inertials, simple cylinders as
//! visual and collision geometry, and the drives' torque limits.
//!
//! Each DH joint transform is `Rz(q) · C_j` with a constant `C_j = Rz(θ₀)·Tz(d)·Tx(a)·Rx(α)`
//! (`·Ry(β)` on the Hayati joints): URDF joint j+1 turns about its own z axis, its origin is
//! `C_j` of the joint before (identity for joint 1: the base), and the tool is a fixed joint
//! at `C_6 · tool`. The forward kinematics of the URDF is therefore the model's *rigid* FK
//! exactly (tested to 1e-9 m from the XML alone, and against Pinocchio); joint compliance and
//! the joint errors `pa10 discover` may add are not kinematics and stay with the daemon, which
//! puts the link where the URDF's joint values say.
//!
//! **Inertials.** DH frame k is URDF link k's frame times `C_{k-1}`, so a model body fixed to
//! DH frame k (mass, centre of mass) becomes link k's inertial at `C_{k-1}·com`; several bodies
//! on one frame are lumped (total mass, mass-weighted centre). The model's gravity torques are
//! therefore the URDF's (tested against Pinocchio's `computeGeneralizedGravity`). The model has
//! no inertia tensors and none are published for the PA10 (`pa10-facts.md` §2.3): each body's
//! tensor is a solid cylinder's (radius [`LINK_RADII_M`], along its centre-of-mass offset, at
//! least 0.1 m long), an approximation stated in the file.
//!
//! **Geometry.** Link k is drawn as a cylinder of radius [`LINK_RADII_M`]`[k]` from its joint
//! to the next joint's origin (a sphere where the two coincide); the same shape is its
//! collision geometry.

use std::fmt::Write;

use nalgebra::{Matrix3, Point3, UnitQuaternion, Vector3};

use super::{Frame, Model};

/// Joint names, `pa10_joint_1` … `pa10_joint_6`.
pub const JOINT_NAMES: [&str; 6] = [
    "pa10_joint_1",
    "pa10_joint_2",
    "pa10_joint_3",
    "pa10_joint_4",
    "pa10_joint_5",
    "pa10_joint_6",
];

/// Radii of the links' cylinders, m (display and collision geometry, and the inertia
/// approximation): shoulder column, upper arm, elbow, forearm, wrist, flange.
pub const LINK_RADII_M: [f64; 6] = [0.09, 0.075, 0.065, 0.06, 0.05, 0.045];

/// Shortest cylinder an inertia tensor is computed for, m.
const MIN_INERTIA_LENGTH_M: f64 = 0.1;

/// `xyz` and `rpy` (URDF: fixed-axis roll, pitch, yaw; R = Rz·Ry·Rx) of a frame.
fn origin(f: &Frame) -> String {
    let t = f.translation.vector;
    let (r, p, y) = f.rotation.euler_angles();
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        t.x, t.y, t.z, r, p, y
    )
}

/// The rotation that takes the z axis onto `d` (any when `d` is zero).
fn z_onto(d: &Vector3<f64>) -> UnitQuaternion<f64> {
    let z = Vector3::z();
    UnitQuaternion::rotation_between(&z, d).unwrap_or_else(|| {
        if d.dot(&z) < 0.0 {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        } else {
            UnitQuaternion::identity()
        }
    })
}

/// Inertia tensor about its centre of a solid cylinder (mass `m` kg, radius `r` and length
/// `l` m) whose axis is along `axis` (any length), kg·m².
fn cylinder_inertia(m: f64, r: f64, l: f64, axis: &Vector3<f64>) -> Matrix3<f64> {
    let across = m * (3.0 * r * r + l * l) / 12.0;
    let along = m * r * r / 2.0;
    let rot = z_onto(axis).to_rotation_matrix();
    let local = Matrix3::from_diagonal(&Vector3::new(across, across, along));
    rot.matrix() * local * rot.matrix().transpose()
}

/// One link's lumped inertial in its URDF frame: mass (kg), centre (m), tensor about the
/// centre (kg·m²).
fn link_inertial(
    model: &Model,
    link: usize,
    c: &Frame,
) -> Option<(f64, Vector3<f64>, Matrix3<f64>)> {
    let parts: Vec<(f64, Vector3<f64>)> = model
        .data()
        .bodies
        .iter()
        .filter(|b| b.frame == link && b.mass > 0.0)
        .map(|b| (b.mass, (c * Point3::from(b.com)).coords))
        .collect();
    let mass: f64 = parts.iter().map(|p| p.0).sum();
    if mass <= 0.0 {
        return None;
    }
    let centre = parts.iter().map(|(m, p)| p * *m).sum::<Vector3<f64>>() / mass;
    let r = LINK_RADII_M[link - 1];
    let mut inertia = Matrix3::zeros();
    for (m, p) in &parts {
        let axis = if p.norm() > 0.01 { *p } else { Vector3::z() };
        let l = (2.0 * p.norm()).max(MIN_INERTIA_LENGTH_M);
        // the body's own cylinder, moved to the lumped centre (parallel axes)
        let s = p - centre;
        inertia += cylinder_inertia(*m, r, l, &axis)
            + *m * (Matrix3::identity() * s.norm_squared() - s * s.transpose());
    }
    Some((mass, centre, inertia))
}

/// The URDF (XML text) of `model`, named `name`: links `base_link`, `pa10_link_1` …
/// `pa10_link_6`, `tool0`; revolute joints with the model's position and speed limits and
/// the torque limits `effort_nm` (N·m); each link's inertial from the model's bodies, and a
/// cylinder as its visual and collision geometry.
pub fn urdf(model: &Model, name: &str, effort_nm: &[f64; 6]) -> String {
    let f = model.frames(&[0.0; 6]);
    let lim = model.limits();
    let mut s = String::new();
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(
        s,
        "<!-- {}: generated by pa10 urdf. Kinematics: the model's rigid kinematics (DH with departures,\n     Hayati beta as joint origins); compliance is compensated by pa10d, not modelled here.\n     Inertials: the model's bodies (mass, centre of mass); the tensors are solid cylinders, an\n     approximation (none is published). Geometry: cylinders sized for display. Efforts: torque\n     limits, N m, as given to pa10 urdf. -->",
        xml_escape(name)
    );
    let _ = writeln!(s, "<robot name=\"{}\">", xml_escape(name));
    let _ = writeln!(s, "  <link name=\"base_link\"/>");
    for j in 0..6 {
        let parent = if j == 0 {
            "base_link".to_string()
        } else {
            format!("pa10_link_{j}")
        };
        // the constant part of the transform before this joint, and after it (to the next
        // joint's origin, or the flange)
        let before = if j == 0 {
            Frame::identity()
        } else {
            f[j - 1].inverse() * f[j]
        };
        let after = f[j].inverse() * f[j + 1];
        let _ = writeln!(s, "  <link name=\"pa10_link_{}\">", j + 1);
        if let Some((m, c, i)) = link_inertial(model, j + 1, &after) {
            let _ = writeln!(
                s,
                "    <inertial>\n      <origin xyz=\"{} {} {}\" rpy=\"0 0 0\"/>\n      <mass value=\"{m}\"/>\n      <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>\n    </inertial>",
                c.x,
                c.y,
                c.z,
                i[(0, 0)],
                i[(0, 1)],
                i[(0, 2)],
                i[(1, 1)],
                i[(1, 2)],
                i[(2, 2)]
            );
        }
        let shape = geometry(&after.translation.vector, LINK_RADII_M[j]);
        for tag in ["visual", "collision"] {
            let _ = writeln!(s, "    <{tag}>\n{shape}    </{tag}>");
        }
        let _ = writeln!(s, "  </link>");
        let _ = writeln!(
            s,
            "  <joint name=\"{}\" type=\"revolute\">\n    <parent link=\"{parent}\"/>\n    <child link=\"pa10_link_{}\"/>\n    {}\n    <axis xyz=\"0 0 1\"/>\n    <limit lower=\"{}\" upper=\"{}\" velocity=\"{}\" effort=\"{}\"/>\n  </joint>",
            JOINT_NAMES[j],
            j + 1,
            origin(&before),
            lim.lower[j],
            lim.upper[j],
            lim.velocity[j],
            effort_nm[j]
        );
    }
    let tool = f[5].inverse() * f[6] * model.tool();
    let _ = writeln!(s, "  <link name=\"tool0\"/>");
    let _ = writeln!(
        s,
        "  <joint name=\"pa10_tool_joint\" type=\"fixed\">\n    <parent link=\"pa10_link_6\"/>\n    <child link=\"tool0\"/>\n    {}\n  </joint>",
        origin(&tool)
    );
    let _ = writeln!(s, "</robot>");
    s
}

/// A cylinder of radius `r` from the link's origin to `to` (m, link frame), or a sphere when
/// `to` is (nearly) the origin: the `<origin>` and `<geometry>` elements.
fn geometry(to: &Vector3<f64>, r: f64) -> String {
    let len = to.norm();
    if len < 1e-3 {
        return format!(
            "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>\n      <geometry><sphere radius=\"{r}\"/></geometry>\n"
        );
    }
    let mid = to / 2.0;
    let (rr, p, y) = z_onto(to).euler_angles();
    format!(
        "      <origin xyz=\"{} {} {}\" rpy=\"{rr} {p} {y}\"/>\n      <geometry><cylinder radius=\"{r}\" length=\"{len}\"/></geometry>\n",
        mid.x, mid.y, mid.z
    )
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cylinders_tensor_turns_with_its_axis() {
        let along_z = cylinder_inertia(2.0, 0.1, 0.5, &Vector3::z());
        let along_x = cylinder_inertia(2.0, 0.1, 0.5, &Vector3::x());
        assert!((along_z[(2, 2)] - 2.0 * 0.01 / 2.0).abs() < 1e-15);
        assert!((along_x[(0, 0)] - along_z[(2, 2)]).abs() < 1e-12);
        assert!((along_x[(2, 2)] - along_z[(0, 0)]).abs() < 1e-12);
        // a tensor about the centre is symmetric and its eigenvalues obey the triangle rule
        let e = along_x.symmetric_eigen().eigenvalues;
        assert!(e[0] + e[1] >= e[2] && e[1] + e[2] >= e[0] && e[0] + e[2] >= e[1]);
    }

    #[test]
    fn every_body_of_the_model_is_in_the_urdf_once() {
        let m = Model::nominal();
        let total: f64 = m.data().bodies.iter().map(|b| b.mass).sum();
        let text = urdf(&m, "pa10", &[1.0; 6]);
        let in_urdf: f64 = text
            .split("<mass value=\"")
            .skip(1)
            .map(|t| {
                t.split('"')
                    .next()
                    .and_then(|v| v.parse::<f64>().ok())
                    .unwrap_or(f64::NAN)
            })
            .sum();
        assert!((in_urdf - total).abs() < 1e-9, "{in_urdf} vs {total}");
        assert_eq!(text.matches("<visual>").count(), 6);
        assert_eq!(text.matches("effort=\"1\"").count(), 6);
    }
}
