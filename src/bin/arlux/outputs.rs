//! What a run will write, checked before any work: each output's name says
//! what it holds (an EXR ends in `.exr`), no two outputs share a path, no
//! output is a folder or lies in a missing one, and no output overwrites a
//! file the run reads (the scene's photo, meshes, references).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Result, bail};

/// One file or folder a command writes, with the flag that names it.
pub(crate) struct Output<'a> {
    pub path: &'a Path,
    pub flag: &'static str,
    /// The extensions a file may have (lower case), or none for a folder.
    pub extensions: &'static [&'static str],
}

impl<'a> Output<'a> {
    pub fn file(path: &'a Path, flag: &'static str, extensions: &'static [&'static str]) -> Self {
        Output {
            path,
            flag,
            extensions,
        }
    }

    pub fn folder(path: &'a Path, flag: &'static str) -> Self {
        Output {
            path,
            flag,
            extensions: &[],
        }
    }
}

/// The run's outputs, canonical, for [`refuse_inputs`] once a scene is loaded.
static OUTPUTS: OnceLock<Vec<(PathBuf, &'static str)>> = OnceLock::new();

/// A path as the file system will resolve it, whether or not it exists yet.
fn canonical(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let parent = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    match (parent.canonicalize(), path.file_name()) {
        (Ok(dir), Some(name)) => dir.join(name),
        _ => path.to_path_buf(),
    }
}

fn refuse(path: &Path, flag: &str, message: String) -> anyhow::Error {
    arlux::Error::file(path, format!("{flag}: {message}")).into()
}

/// Whether a file can be created in `dir`: creates and removes a probe (the
/// permissions alone do not tell: a read-only mount, another user's folder).
fn probe(dir: &Path) -> std::io::Result<()> {
    let path = dir.join(format!(".arlux-probe-{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&path)?;
    std::fs::remove_file(&path)
}

/// Checks every output before any work; remembers them for [`refuse_inputs`].
pub(crate) fn check(outputs: &[Output]) -> Result<()> {
    for o in outputs {
        let parent = o
            .path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if o.extensions.is_empty() {
            if o.path.exists() && !o.path.is_dir() {
                return Err(refuse(o.path, o.flag, "is a file, not a folder".into()));
            }
            continue;
        }
        if !parent.is_dir() {
            return Err(refuse(
                o.path,
                o.flag,
                format!(
                    "cannot write: the folder {} does not exist",
                    parent.display()
                ),
            ));
        }
        if o.path.is_dir() {
            return Err(refuse(o.path, o.flag, "is a folder, not a file".into()));
        }
        if let Err(e) = probe(parent) {
            return Err(refuse(
                o.path,
                o.flag,
                format!("cannot write in the folder {}: {e}", parent.display()),
            ));
        }
        let ext = o
            .path
            .extension()
            .map(|e| e.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        if !o.extensions.contains(&ext.as_str()) {
            return Err(refuse(
                o.path,
                o.flag,
                format!(
                    "the name must end in .{} (what is written there), not '{}'",
                    o.extensions.join(" or ."),
                    o.path
                        .file_name()
                        .map_or_else(String::new, |n| n.to_string_lossy().into())
                ),
            ));
        }
    }
    let resolved: Vec<(PathBuf, &'static str)> = outputs
        .iter()
        .map(|o| (canonical(o.path), o.flag))
        .collect();
    for (i, (a, flag_a)) in resolved.iter().enumerate() {
        if let Some((_, flag_b)) = resolved[i + 1..].iter().find(|(b, _)| b == a) {
            bail!(refuse(
                outputs[i].path,
                flag_a,
                format!("{flag_b} names the same file: each output needs its own")
            ));
        }
    }
    let _ = OUTPUTS.set(resolved);
    Ok(())
}

/// Refuses a run whose outputs include one of its `inputs`.
pub(crate) fn refuse_inputs(inputs: &[PathBuf]) -> Result<()> {
    let Some(outputs) = OUTPUTS.get() else {
        return Ok(());
    };
    for input in inputs {
        let input = canonical(input);
        if let Some((path, flag)) = outputs.iter().find(|(o, _)| *o == input) {
            bail!(refuse(
                path,
                flag,
                "is an input of this run: writing it would destroy it".into()
            ));
        }
    }
    Ok(())
}

/// The outputs of one run, committed together: each is written to a
/// temporary beside it, and all are renamed into place only when every one
/// was written; a failure removes every temporary and every folder the run
/// made (a stopped run's temporaries go with the signal handler's cleanup).
#[derive(Default)]
pub(crate) struct Batch {
    staged: Vec<(PathBuf, PathBuf)>,
    made: Vec<PathBuf>,
}

impl Batch {
    /// Where to write the output `path` for now.
    pub fn stage(&mut self, path: &Path) -> PathBuf {
        let name = path
            .file_name()
            .map_or("out".into(), |n| n.to_string_lossy());
        let tmp = path.with_file_name(format!(".{name}.pending{}", std::process::id()));
        arlux::util::cleanup::register(&tmp);
        self.staged.push((tmp.clone(), path.to_path_buf()));
        tmp
    }

    /// Makes the folder `dir` (and its missing parents), remembering what it made.
    pub fn folder(&mut self, dir: &Path) -> Result<()> {
        let mut missing = Vec::new();
        let mut d = Some(dir);
        while let Some(p) = d.filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
            missing.push(p.to_path_buf());
            d = p.parent();
        }
        std::fs::create_dir_all(dir).map_err(|e| arlux::Error::io(dir, &e))?;
        self.made.extend(missing);
        Ok(())
    }

    /// Writes every output with `write` (given the batch to stage them in),
    /// then renames them into place; on failure nothing of the run is left.
    pub fn run<T>(write: impl FnOnce(&mut Batch) -> Result<T>) -> Result<T> {
        let mut batch = Batch::default();
        let result = write(&mut batch).and_then(|out| batch.commit().map(|()| out));
        if result.is_err() {
            batch.abort();
        }
        result
    }

    fn commit(&mut self) -> Result<()> {
        for (tmp, path) in &self.staged {
            std::fs::rename(tmp, path).map_err(|e| arlux::Error::io(path, &e))?;
            arlux::util::cleanup::unregister(tmp);
        }
        self.staged.clear();
        self.made.clear();
        Ok(())
    }

    fn abort(&mut self) {
        for (tmp, _) in self.staged.drain(..) {
            let _ = std::fs::remove_file(&tmp);
            arlux::util::cleanup::unregister(&tmp);
        }
        // Deepest first; a folder holding anything else stays.
        for dir in self.made.drain(..) {
            let _ = std::fs::remove_dir(&dir);
        }
    }
}
