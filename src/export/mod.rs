//! Writing files: every output is written to a temporary file in the same folder and renamed
//! into place, so an interrupted run leaves either the old file or the new one, never a
//! half-written one. [`write_design`] serialises a design's planned [`Outputs`]; the CAD
//! formats are here ([`step`], [`stl`], [`dxf`], the shop [`drawing`]), the human-facing ones
//! in [`crate::render`]. Exporters read and never decide: what is made is
//! [`crate::outputs::plan`]'s choice.

pub mod drawing;
pub mod dxf;
pub mod folder;
pub mod step;
pub mod stl;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::design::Design;
use crate::outputs::Outputs;
use crate::render;

/// Why an output could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Produced by [`write_atomic`] (and so every writer) when the OS refuses the write.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Produced by [`write_atomic`] and [`folder::write_set`] for a path that must not be
    /// written: a device, a pipe or anything else that is not a regular file (or a folder).
    #[error("cannot write {path}: {why}")]
    NotWritable {
        /// The path.
        path: PathBuf,
        /// Why not.
        why: String,
    },
    /// Produced by [`folder::write_set`] when another run holds the folder.
    #[error(
        "{path} is being written by another camspring run; wait for it to finish (the folder \
         is locked while a run writes it, so two runs never mix their files)"
    )]
    Busy {
        /// The folder.
        path: PathBuf,
    },
    /// Produced by [`write_design`] when an output cannot be encoded.
    #[error("cannot encode {what}: {message}")]
    Encode {
        /// Which output.
        what: &'static str,
        /// Why.
        message: String,
    },
}

fn encode(what: &'static str) -> impl Fn(String) -> ExportError {
    move |message| ExportError::Encode { what, message }
}

/// Temporary files are named `.camspring-PID-*.tmp`.
const TMP_PREFIX: &str = ".camspring-";

/// Whether the process `pid` still runs (on other systems: assume it does).
fn alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        // SAFETY: kill with signal 0 only checks that the process exists.
        let r = unsafe { libc::kill(pid as libc::pid_t, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Removes temporary files that killed runs left in `dir` (their process is gone).
fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let pid = name
            .strip_prefix(TMP_PREFIX)
            .filter(|_| name.ends_with(".tmp"))
            .and_then(|rest| rest.split('-').next())
            .and_then(|p| p.parse::<u32>().ok());
        if pid.is_some_and(|p| !alive(p)) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Refuses an existing `path` that is not a regular file (a device, a pipe, a folder): writing
/// there would replace or feed something that is not an output.
pub fn check_regular(path: &Path) -> Result<(), ExportError> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(ExportError::NotWritable {
            path: path.to_path_buf(),
            why: if m.is_dir() {
                "it is a folder".into()
            } else {
                "it is not a regular file (a device, a pipe or a socket); give a file name".into()
            },
        }),
        _ => Ok(()),
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename).
/// An existing `path` that is not a regular file is refused.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes)?;
    file.commit()
}

/// A file written as it is computed (a long time series) and put in place only when complete:
/// the bytes go to a temporary file in the same folder, renamed over `path` by
/// [`AtomicFile::commit`]. Dropped without a commit, it leaves `path` as it was.
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    out: std::io::BufWriter<tempfile::NamedTempFile>,
}

impl AtomicFile {
    /// Starts the temporary file for `path` (whose folder is created). An existing `path` that
    /// is not a regular file is refused.
    pub fn create(path: &Path) -> Result<AtomicFile, ExportError> {
        check_regular(path)?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let wrap = |source| ExportError::Write {
            path: path.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(wrap)?;
        remove_stale_temporaries(dir);
        let mut builder = tempfile::Builder::new();
        let prefix = format!("{TMP_PREFIX}{}-", std::process::id());
        builder.prefix(&prefix).suffix(".tmp");
        #[cfg(unix)]
        {
            // tempfile creates 0600; outputs are ordinary readable files.
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o644));
        }
        let tmp = builder.tempfile_in(dir).map_err(wrap)?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            out: std::io::BufWriter::with_capacity(1 << 20, tmp),
        })
    }

    fn error(&self, source: std::io::Error) -> ExportError {
        ExportError::Write {
            path: self.path.clone(),
            source,
        }
    }

    /// Appends bytes.
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<(), ExportError> {
        self.out.write_all(bytes).map_err(|e| self.error(e))
    }

    /// Empties the file, to write it again from its start.
    pub fn restart(&mut self) -> Result<(), ExportError> {
        use std::io::Seek;
        self.out.flush().map_err(|e| self.error(e))?;
        let file = self.out.get_mut().as_file_mut();
        file.set_len(0)
            .and_then(|()| file.rewind())
            .map_err(|e| ExportError::Write {
                path: self.path.clone(),
                source: e,
            })
    }

    /// Flushes, syncs and renames the file into place.
    pub fn commit(self) -> Result<(), ExportError> {
        let path = self.path;
        let wrap = |source| ExportError::Write {
            path: path.clone(),
            source,
        };
        let tmp = self.out.into_inner().map_err(|e| wrap(e.into_error()))?;
        tmp.as_file().sync_all().map_err(wrap)?;
        tmp.persist(&path).map_err(|e| wrap(e.error))?;
        Ok(())
    }
}

/// Puts the run's identity into an SVG document as a comment right after its root tag.
fn mark_svg(bytes: Vec<u8>, run_id: &str) -> Vec<u8> {
    let text = String::from_utf8_lossy(&bytes);
    match text
        .find("<svg")
        .and_then(|i| text[i..].find('>').map(|j| i + j + 1))
    {
        Some(at) => format!(
            "{}\n<!-- camspring run {run_id} -->{}",
            &text[..at],
            &text[at..]
        )
        .into_bytes(),
        None => bytes,
    }
}

/// The bytes of one output the plan lists, by its file name.
fn render_file(design: &Design, outputs: &Outputs, name: &str) -> Result<Vec<u8>, ExportError> {
    let spec = &design.spec;
    let part = || {
        outputs
            .part
            .as_ref()
            .ok_or_else(|| encode("the part files")("the plan holds no part".into()))
    };
    let program = || {
        outputs
            .program
            .as_ref()
            .ok_or_else(|| encode("cam.ngc")("the plan holds no program".into()))
    };
    Ok(match name {
        "design.json" => serde_json::to_vec_pretty(&outputs.summary)
            .map_err(|e| encode("design.json")(e.to_string()))?,
        "report.html" => {
            let force = render::design::force_svg(design, outputs.summary.force_band.as_ref());
            let profile = render::design::profile_svg(design);
            render::html::report_html(design, &outputs.summary, &force, &profile).into_bytes()
        }
        "profile.csv" => {
            render::design::profile_csv(design).map_err(|e| encode("profile.csv")(e.to_string()))?
        }
        "force.svg" => {
            render::design::force_svg(design, outputs.summary.force_band.as_ref()).into_bytes()
        }
        "profile.svg" => render::design::profile_svg(design).into_bytes(),
        "cam.step" => step::step_text(&part()?.part, &spec.name, &outputs.summary.run_id)
            .map_err(|e| encode("cam.step")(e.to_string()))?
            .into_bytes(),
        "cam.stl" => stl::stl_bytes(&part()?.mesh, &outputs.summary.run_id),
        "cam.dxf" => {
            dxf::dxf_bytes(&part()?.part, &outputs.summary.run_id).map_err(encode("cam.dxf"))?
        }
        "drawing.svg" => drawing::drawing_svg(design, &part()?.part).into_bytes(),
        "drawing.pdf" => drawing::drawing_pdf(&drawing::drawing_svg(design, &part()?.part))
            .map_err(|e| encode("drawing.pdf")(e.to_string()))?,
        "cam.ngc" => program()?.text.clone().into_bytes(),
        "toolpath.svg" => {
            render::design::toolpath_svg(design, &part()?.part, &program()?.jobs).into_bytes()
        }
        other => return Err(encode("an output")(format!("no writer for \"{other}\""))),
    })
}

/// The bytes of every file the plan lists, in writing order: `design.json` last, so that its
/// presence with this run's content marks a complete set.
pub fn design_files(
    design: &Design,
    outputs: &Outputs,
) -> Result<Vec<(String, Vec<u8>)>, ExportError> {
    let mut names: Vec<&str> = outputs.summary.outputs.iter().map(String::as_str).collect();
    names.sort_by_key(|n| *n == "design.json");
    names
        .into_iter()
        .map(|n| {
            let mut bytes = render_file(design, outputs, n)?;
            if n.ends_with(".svg") {
                bytes = mark_svg(bytes, &outputs.summary.run_id);
            }
            Ok((n.to_string(), bytes))
        })
        .collect()
}

/// Writes the planned outputs of a design as the new content of `dir`, replacing the
/// previous run as a whole ([`folder::write_set`]): files of the previous run that this run
/// does not make (a refused part's STEP, a refused program) are gone, the user's own files
/// stay. Returns the paths written.
pub fn write_design(
    design: &Design,
    outputs: &Outputs,
    dir: &Path,
) -> Result<Vec<PathBuf>, ExportError> {
    let files = design_files(design, outputs)?;
    folder::write_set(dir, &files, &crate::outputs::ALL_OUTPUTS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_streamed_file_appears_only_when_committed_and_a_restart_empties_it() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let path = dir.path().join("est.csv");
        std::fs::write(&path, "the previous run\n").expect("write");
        let mut file = AtomicFile::create(&path).expect("create");
        file.write_all(b"a first attempt that diverged\n")
            .expect("write");
        file.restart().expect("restart");
        file.write_all(b"t_s\n1.0\n").expect("write");
        // Until the commit the previous file stands.
        assert_eq!(
            std::fs::read_to_string(&path).expect("read"),
            "the previous run\n"
        );
        file.commit().expect("commit");
        assert_eq!(std::fs::read_to_string(&path).expect("read"), "t_s\n1.0\n");
        // Dropped without a commit, a file leaves nothing behind.
        let other = dir.path().join("other.csv");
        drop(AtomicFile::create(&other).expect("create"));
        assert!(!other.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .expect("list")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(left.len(), 1, "{left:?}");
    }
}
