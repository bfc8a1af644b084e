//! Where a virtual object goes: `translate`, `scale`, and a rotation given
//! as `rotate_y_deg`, `rotate = [x, y, z]` (degrees, Blender's XYZ Euler),
//! `quaternion = [w, x, y, z]`, or a whole 4×4 `matrix` (rows, as Blender's
//! `matrix_world` prints) that holds translation, rotation and a uniform scale.

use glam::{DMat3, DQuat, DVec3};

use super::PoseChange;
use super::fields::{Fields, number};
use crate::error::Result;

/// The keys of a placement that `fields` gives (none given: no change).
pub(super) fn pose_change(f: &Fields) -> Result<PoseChange> {
    f.allow(&[
        "translate",
        "scale",
        "rotate_y_deg",
        "rotate",
        "quaternion",
        "matrix",
    ]);
    if f.has("matrix") {
        for k in ["translate", "scale", "rotate_y_deg", "rotate", "quaternion"] {
            if f.has(k) {
                return Err(f.error(
                    k,
                    "the matrix already places the object: give one or the other",
                ));
            }
        }
        return matrix(f);
    }
    let given: Vec<&str> = ["rotate_y_deg", "rotate", "quaternion"]
        .into_iter()
        .filter(|k| f.has(k))
        .collect();
    if given.len() > 1 {
        return Err(f.error(
            given[1],
            format!("give one rotation: {} is given too", given[0]),
        ));
    }
    let rotation = if let Some(deg) = f.opt_f64("rotate_y_deg")? {
        Some(super::Pose::about_y(deg))
    } else if let Some(r) = f.opt_vec3("rotate")? {
        let [x, y, z] = r.to_array().map(f64::to_radians);
        Some(DMat3::from_rotation_z(z) * DMat3::from_rotation_y(y) * DMat3::from_rotation_x(x))
    } else if let Some(q) = f.get("quaternion") {
        Some(quaternion(q).map_err(|m| f.error("quaternion", m))?)
    } else {
        None
    };
    let scale = f.opt_f64("scale")?;
    if scale.is_some_and(|s| s <= 0.0) {
        return Err(f.error("scale", "must be positive"));
    }
    Ok(PoseChange {
        translate: f.opt_place("translate")?,
        rotation,
        scale,
    })
}

fn quaternion(v: &toml::Value) -> std::result::Result<DMat3, String> {
    let items = v
        .as_array()
        .filter(|a| a.len() == 4)
        .ok_or("must be [w, x, y, z]")?;
    let q: Vec<f64> = items
        .iter()
        .map(number)
        .collect::<std::result::Result<_, _>>()?;
    let q = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
    if q.length().is_nan() || q.length() <= 1e-9 {
        return Err("must not be zero".into());
    }
    Ok(DMat3::from_quat(q.normalize()))
}

/// A 4×4 row-major matrix: its last row 0 0 0 1, its upper 3×3 a rotation
/// times one positive scale (no shear, no mirror, no non-uniform scale).
fn matrix(f: &Fields) -> Result<PoseChange> {
    let bad = |m: String| f.error("matrix", m);
    let rows = f
        .get("matrix")
        .and_then(|v| v.as_array())
        .filter(|r| r.len() == 4)
        .ok_or_else(|| bad("must be 4 rows of 4 numbers".into()))?;
    let mut m = [[0.0; 4]; 4];
    for (i, row) in rows.iter().enumerate() {
        let row = row
            .as_array()
            .filter(|r| r.len() == 4)
            .ok_or_else(|| bad(format!("row {i} must hold 4 numbers")))?;
        for (j, v) in row.iter().enumerate() {
            m[i][j] = number(v).map_err(|e| bad(format!("row {i}: {e}")))?;
        }
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(bad(format!(
            "its last row is {:?}, not [0, 0, 0, 1]: not a placement",
            m[3]
        )));
    }
    let linear = DMat3::from_cols(
        DVec3::new(m[0][0], m[1][0], m[2][0]),
        DVec3::new(m[0][1], m[1][1], m[2][1]),
        DVec3::new(m[0][2], m[1][2], m[2][2]),
    );
    let det = linear.determinant();
    if det.is_nan() || det <= 0.0 {
        return Err(bad(format!(
            "its 3×3 part has determinant {det}: it mirrors or flattens the object"
        )));
    }
    let scale = det.cbrt();
    let rotation = linear / scale;
    let off = (rotation.transpose() * rotation - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    if off > 1e-4 {
        return Err(bad(format!(
            "its 3×3 part is not a rotation times one scale (off by {off:.1e}): arlux scales objects uniformly, without shear"
        )));
    }
    let translate = DVec3::new(m[0][3], m[1][3], m[2][3]);
    let max = crate::geometry::MAX_COORDINATE as f64;
    if translate.abs().max_element() > max {
        return Err(bad(format!(
            "its translation {translate} lies beyond ±{max} m"
        )));
    }
    Ok(PoseChange {
        translate: Some(translate),
        rotation: Some(rotation),
        scale: Some(scale),
    })
}
