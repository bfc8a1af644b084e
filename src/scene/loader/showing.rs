//! Which objects a command shows, read from the scene's table before its
//! objects are: the loader reads only their meshes (a variant's render does
//! not pay for objects it hides or leaves disabled).

use std::collections::HashSet;

/// What a command will show of the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Showing<'a> {
    /// Every object may be shown (a session that edits the scene, `info`).
    Everything,
    /// The scene as written: its enabled objects.
    Base,
    /// A variant's objects.
    Variant(&'a str),
    /// A motion's poses: what its `variant` shows (else the enabled
    /// objects) less what it hides, and the object that moves.
    Motion(&'a str),
}

/// The names of the objects `showing` shows, or None to read every mesh:
/// for `Everything`, and for a table this cannot follow (a missing name, a
/// value of the wrong type), which the full reading then reports by key.
pub(in crate::scene) fn shown_names(
    table: &toml::Table,
    showing: Showing,
) -> Option<HashSet<String>> {
    if showing == Showing::Everything {
        return None;
    }
    let mut shown = HashSet::new();
    let objects = table
        .get("virtual")
        .map_or(Some(&[][..]), |v| v.as_array().map(|a| a.as_slice()))?;
    for o in objects {
        let t = o.as_table()?;
        let enabled = t.get("enabled").map_or(Some(true), |e| e.as_bool())?;
        if enabled {
            shown.insert(t.get("name")?.as_str()?.to_string());
        }
    }
    let named = |key: &str, name: &str| -> Option<toml::Table> {
        let all = table.get(key)?.as_array()?;
        (all.iter().filter_map(|t| t.as_table()))
            .find(|t| t.get("name").and_then(|n| n.as_str()) == Some(name))
            .cloned()
    };
    // A variant's (or a motion's) hidden names go, its posed objects come.
    let change = |t: &toml::Table, shown: &mut HashSet<String>| -> Option<()> {
        if let Some(hide) = t.get("hide") {
            for n in hide.as_array()? {
                shown.remove(n.as_str()?);
            }
        }
        if let Some(objects) = t.get("objects") {
            shown.extend(objects.as_table()?.keys().cloned());
        }
        Some(())
    };
    match showing {
        Showing::Everything | Showing::Base => {}
        Showing::Variant(v) => change(&named("variant", v)?, &mut shown)?,
        Showing::Motion(m) => {
            let t = named("motion", m)?;
            if let Some(v) = t.get("variant") {
                change(&named("variant", v.as_str()?)?, &mut shown)?;
            }
            change(&t, &mut shown)?;
            shown.insert(t.get("object")?.as_str()?.to_string());
        }
    }
    Some(shown)
}
