//! A scene's `[[variant]]` and `[[motion]]` tables, each checked against
//! the scene's lights and objects as it is read.

use super::*;

impl Loader<'_> {
    pub(in crate::scene) fn variant(
        &self,
        v: &Fields,
        lights: &[Light],
        objects: &[VirtualObject],
    ) -> Result<Variant> {
        let name = v.req_str("name")?.to_string();
        let mut variant = Variant {
            name,
            lights: vec![],
            light_positions: vec![],
            objects: vec![],
            hide_objects: vec![],
            hide_lights: vec![],
            reference: None,
            reference_noise: None,
        };
        if let Some(t) = v.opt_table("lights")? {
            for (lname, value) in t.entries() {
                let key = t.key_path(lname);
                let index = lights.iter().position(|l| l.name == lname).ok_or_else(|| {
                    Error::key(self.file, key.clone(), format!("no light named '{lname}'"))
                })?;
                let (scale, position) = self.light_change(&key, value, &lights[index])?;
                if let Some(scale) = scale {
                    variant.lights.push((index, scale));
                }
                if let Some(p) = position {
                    variant.light_positions.push((index, p));
                }
            }
        }
        if let Some(t) = v.opt_table("objects")? {
            for (oname, value) in t.entries() {
                let key = t.key_path(oname);
                let index = objects
                    .iter()
                    .position(|o| o.name == oname)
                    .ok_or_else(|| {
                        Error::key(
                            self.file,
                            key.clone(),
                            format!("no virtual object named '{oname}'"),
                        )
                    })?;
                let p = Fields::new(self.file, key.clone(), value)?;
                let change = super::placement::pose_change(&p)?;
                p.finish()?;
                let o = &objects[index];
                let pose = change.applied_to(&o.pose);
                within_reach(o, &pose).map_err(|m| Error::key(self.file, key.clone(), m))?;
                variant.objects.push((index, change));
            }
        }
        if let Some(items) = v.opt_array("hide")? {
            self.hide(items, lights, objects, &mut variant)?;
        }
        if let Some(rel) = v.opt_str("reference")? {
            variant.reference = Some(self.reference_path(v, "reference", rel)?);
        }
        let declared = reference_noise(v, variant.reference.is_some())?;
        let twin = match v.opt_str("reference_twin")? {
            Some(_) if variant.reference.is_none() => {
                return Err(v.error("reference_twin", "a twin needs the variant's reference"));
            }
            Some(rel) => Some(self.reference_path(v, "reference_twin", rel)?),
            None => None,
        };
        variant.reference_noise = match (declared, twin) {
            (Some(_), Some(_)) => {
                return Err(v.error(
                    "reference_twin",
                    "give reference_noise or reference_twin, not both",
                ));
            }
            (Some(n), None) => Some(super::ReferenceNoise::Declared(n)),
            (None, Some(t)) => Some(super::ReferenceNoise::Twin(t)),
            (None, None) => None,
        };
        v.finish()?;
        Ok(variant)
    }

    /// A variant's change of one light: a number is its scale; a table
    /// `{ scale, position }` may also move a virtual light (a real one stays
    /// where the photo has it).
    fn light_change(
        &self,
        key: &str,
        value: &toml::Value,
        light: &Light,
    ) -> Result<(Option<f64>, Option<DVec3>)> {
        let (scale, position) = match value {
            toml::Value::Table(_) => {
                let f = Fields::new(self.file, key.to_string(), value)?;
                let scale = f.opt_f64("scale")?;
                let position = f.opt_place("position")?;
                f.finish()?;
                if scale.is_none() && position.is_none() {
                    return Err(f.table_error("give scale, position or both"));
                }
                if position.is_some() && (light.real || light.known_position().is_none()) {
                    return Err(f.error(
                        "position",
                        format!(
                            "'{}' is a real light: it stays where the photo has it (a virtual light, real = false, can move)",
                            light.name
                        ),
                    ));
                }
                (scale, position)
            }
            v => {
                let s = fields::number(v).map_err(|m| Error::key(self.file, key, m))?;
                (Some(s), None)
            }
        };
        if scale.is_some_and(|s| s < 0.0) {
            return Err(Error::key(
                self.file,
                key,
                "a light's scale must not be negative",
            ));
        }
        Ok((scale, position))
    }

    /// A `hide` list's names, each a virtual object or a light, added to
    /// `variant`'s hidden ones (an error for a name it poses or scales).
    fn hide(
        &self,
        items: Vec<(String, &toml::Value)>,
        lights: &[Light],
        objects: &[VirtualObject],
        variant: &mut Variant,
    ) -> Result<()> {
        for (path, item) in items {
            let toml::Value::String(n) = item else {
                return Err(Error::key(
                    self.file,
                    path,
                    "must be the name of a virtual object or light",
                ));
            };
            if let Some(o) = objects.iter().position(|o| &o.name == n) {
                if variant.objects.iter().any(|(i, _)| *i == o) {
                    return Err(Error::key(
                        self.file,
                        path,
                        format!("'{n}' is both posed and hidden"),
                    ));
                }
                variant.hide_objects.push(o);
            } else if let Some(l) = lights.iter().position(|l| &l.name == n) {
                if variant.lights.iter().any(|(i, _)| *i == l) {
                    return Err(Error::key(
                        self.file,
                        path,
                        format!("'{n}' is both given a scale and hidden"),
                    ));
                }
                variant.hide_lights.push(l);
            } else {
                return Err(Error::key(
                    self.file,
                    path,
                    format!("no virtual object or light named '{n}'"),
                ));
            }
        }
        Ok(())
    }

    /// What a motion's poses start from: the variant it names (`variant`),
    /// with what it hides (`hide`) hidden too; None for the scene as
    /// written. The motion may not hide the moving object, nor the variant
    /// pose it (a variant hiding it shows it in the motion).
    fn motion_start(
        &self,
        m: &Fields,
        lights: &[Light],
        objects: &[VirtualObject],
        variants: &[Variant],
        object: usize,
    ) -> Result<Option<Variant>> {
        let named = |v: &str| variants.iter().find(|x| x.name == v).cloned();
        let mut start = match m.opt_str("variant")? {
            None => None,
            Some(v) => Some(named(v).ok_or_else(|| {
                m.error(
                    "variant",
                    format!("no variant named '{v}' (before this motion)"),
                )
            })?),
        };
        // A variant that hides the moving object (a light change without
        // it) still shows it in the motion.
        if let Some(s) = &mut start {
            s.hide_objects.retain(|&o| o != object);
        }
        if let Some(items) = m.opt_array("hide")? {
            let s = start.get_or_insert_with(|| Variant {
                name: String::new(),
                lights: vec![],
                light_positions: vec![],
                objects: vec![],
                hide_objects: vec![],
                hide_lights: vec![],
                reference: None,
                reference_noise: None,
            });
            self.hide(items, lights, objects, s)?;
        }
        if let Some(s) = &start {
            let moving = &objects[object].name;
            if s.hide_objects.contains(&object) {
                return Err(m.error("hide", format!("hides '{moving}', which this motion moves")));
            }
            if s.objects.iter().any(|(o, _)| *o == object) {
                return Err(m.error(
                    "variant",
                    format!("poses '{moving}', which this motion moves: give the motion's translations alone"),
                ));
            }
        }
        Ok(start)
    }

    pub(in crate::scene) fn motion(
        &self,
        m: &Fields,
        lights: &[Light],
        objects: &[VirtualObject],
        variants: &[Variant],
    ) -> Result<Motion> {
        let name = m.req_str("name")?.to_string();
        let oname = m.req_str("object")?;
        let object = objects
            .iter()
            .position(|o| o.name == oname)
            .ok_or_else(|| m.error("object", format!("no virtual object named '{oname}'")))?;
        let start = self.motion_start(m, lights, objects, variants, object)?;
        let items = m
            .opt_array("translations")?
            .ok_or_else(|| m.error("translations", "missing"))?;
        if items.is_empty() {
            return Err(m.error("translations", "needs at least one pose"));
        }
        let translations = items
            .iter()
            .map(|(path, v)| {
                let translate =
                    fields::place(v).map_err(|msg| Error::key(self.file, path.clone(), msg))?;
                let o = &objects[object];
                let pose = Pose {
                    translate,
                    ..o.pose
                };
                within_reach(o, &pose).map_err(|msg| Error::key(self.file, path.clone(), msg))?;
                Ok(translate)
            })
            .collect::<Result<Vec<_>>>()?;
        let mut references = Vec::new();
        if let Some(refs) = m.opt_array("references")? {
            if refs.len() != translations.len() {
                return Err(m.error(
                    "references",
                    format!(
                        "{} references for {} poses: give one per pose",
                        refs.len(),
                        translations.len()
                    ),
                ));
            }
            for (path, v) in refs {
                let toml::Value::String(rel) = v else {
                    return Err(Error::key(self.file, path, "must be a file name"));
                };
                references.push(self.dir.join(rel));
            }
        }
        let reference_noise = reference_noise(m, !references.is_empty())?;
        m.finish()?;
        Ok(Motion {
            name,
            object,
            start,
            translations,
            references,
            reference_noise,
        })
    }
}

/// A variant's or motion's `reference_noise`: a relative RMSE in [0, 1),
/// given only with references.
fn reference_noise(t: &Fields, has_reference: bool) -> Result<Option<f64>> {
    let Some(n) = t.opt_f64("reference_noise")? else {
        return Ok(None);
    };
    if !has_reference {
        return Err(t.error("reference_noise", "describes a reference: give one"));
    }
    if !(n.is_finite() && (0.0..1.0).contains(&n)) {
        return Err(t.error(
            "reference_noise",
            format!("a relative RMSE in [0, 1) (0.0105 is 1.05%), not {n}"),
        ));
    }
    Ok(Some(n))
}
