//! Saving the session's state: a `[[variant]]` appended to the scene's
//! text (with the objects added from `--assets`) in a new file beside it.

use std::path::PathBuf;

use super::Interactive;
use crate::error::{Error, Result};

impl Interactive {
    /// Writes the state as a `[[variant]]` named `name` into a new file
    /// beside the scene, `STEM.NAME.toml`: the scene file's own text with the
    /// variant appended, so that `arlux render` accepts it as it is. The
    /// scene file is never touched, nor an existing file replaced.
    pub fn save_variant(&self, name: &str) -> Result<PathBuf> {
        // Not starting with '-': the name is passed as `--variant NAME`.
        let valid = !name.is_empty()
            && name.len() <= 64
            && !name.starts_with('-')
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !valid || self.base.variants.iter().any(|v| v.name == name) {
            return Err(Error::key(
                &self.base.file,
                "variant",
                format!(
                    "'{name}': a variant's new name is 1-64 letters, digits, '-' or '_', not starting with '-', not one the scene has"
                ),
            ));
        }
        // The session's own text: the saved variant renders what the page
        // shows even if the file was edited meanwhile (`file_changed` says so).
        let text = &self.base.source;
        let mut variant = toml::Table::new();
        variant.insert(
            "variant".into(),
            toml::Value::Array(vec![self.variant_table(name).into()]),
        );
        let appended =
            toml::to_string(&variant).map_err(|e| Error::file(&self.base.file, e.to_string()))?;
        let path = self.variant_file(name);
        let content = format!("{}\n# Saved by arlux serve.\n{appended}", text.trim_end());
        crate::image_io::write_new(&path, content.as_bytes())?;
        Ok(path)
    }

    /// Whether the scene file on disk no longer holds the text the session
    /// was loaded from (an edit made while serving, which the session does
    /// not show and a save does not carry).
    pub fn file_changed(&self) -> bool {
        std::fs::read_to_string(&self.base.file).map_or(true, |t| t != self.file_text)
    }

    /// The file a variant named `name` is saved in: `STEM.NAME.toml` beside the scene.
    fn variant_file(&self, name: &str) -> PathBuf {
        let stem = self
            .base
            .file
            .file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        self.base.dir().join(format!("{stem}.{name}.toml"))
    }

    /// A name `session-N` no file beside the scene and no variant has.
    pub fn next_variant_name(&self) -> String {
        (1..)
            .map(|n| format!("session-{n}"))
            .find(|name| {
                !self.base.variants.iter().any(|v| &v.name == name)
                    && !self.variant_file(name).exists()
            })
            .expect("some number is free")
    }
}
