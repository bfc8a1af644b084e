//! The session's edits of lights: a scale (switch, slider) and, for a
//! virtual light, a place (a click on the photo and a height off the
//! surface seen there). Both are written into the variant as
//! `lights.NAME`: a number, or `{ scale, position }` once moved.

use glam::DVec3;

use super::{MAX_LIGHT_SCALE, Refusal};
use crate::scene::Light;

/// What the user changed of one light (None: as the scene has it).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct LightEdit {
    pub scale: Option<f64>,
    pub position: Option<DVec3>,
}

/// `scale` checked as a light's scale (-0.0 too: it would be written into
/// a variant as a negative scale).
pub(super) fn checked_scale(scale: f64) -> Result<f64, Refusal> {
    if !scale.is_finite() || scale.is_sign_negative() || scale > MAX_LIGHT_SCALE {
        return Err(Refusal::new(
            "scale",
            format!("a light's scale must lie in 0..={MAX_LIGHT_SCALE}"),
        ));
    }
    Ok(scale)
}

/// Refuses to move a light the photo shows: only a virtual light moves.
pub(super) fn movable(light: &Light) -> Result<(), Refusal> {
    if light.real || light.known_position().is_none() {
        return Err(Refusal::new(
            "light",
            format!(
                "'{}' is a real light: it stays where the photo has it (switch it off and place a virtual one)",
                light.name
            ),
        ));
    }
    Ok(())
}

/// The variant's value for `light` after `edit`, if it differs from the scene's.
pub(super) fn variant_value(light: &Light, edit: &LightEdit) -> Option<toml::Value> {
    let scale = edit.scale.filter(|s| *s != light.scale);
    match edit.position {
        None => scale.map(toml::Value::from),
        Some(p) => {
            let mut t = toml::Table::new();
            if let Some(s) = scale {
                t.insert("scale".into(), s.into());
            }
            t.insert("position".into(), super::vec3(p));
            Some(t.into())
        }
    }
}
