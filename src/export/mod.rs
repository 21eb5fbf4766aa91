//! Writing files: every output is written to a temporary file in the same folder and renamed
//! into place, so an interrupted run leaves either the old file or the new one, never a
//! half-written one. [`write_design`] serialises a design's planned [`Outputs`]; the CAD
//! formats are here ([`step`], [`stl`], [`dxf`], the shop [`drawing`]), the human-facing ones
//! in [`crate::render`]. Exporters read and never decide: what is made is
//! [`crate::outputs::plan`]'s choice.

pub mod drawing;
pub mod dxf;
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

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let wrap = |source| ExportError::Write {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(wrap)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".camspring-").suffix(".tmp");
    #[cfg(unix)]
    {
        // tempfile creates 0600; outputs are ordinary readable files.
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(wrap)?;
    tmp.write_all(bytes).map_err(wrap)?;
    tmp.as_file().sync_all().map_err(wrap)?;
    tmp.persist(path).map_err(|e| wrap(e.error))?;
    Ok(())
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
            let force = render::design::force_svg(design);
            let profile = render::design::profile_svg(design);
            render::html::report_html(design, &outputs.summary, &force, &profile).into_bytes()
        }
        "profile.csv" => {
            render::design::profile_csv(design).map_err(|e| encode("profile.csv")(e.to_string()))?
        }
        "force.svg" => render::design::force_svg(design).into_bytes(),
        "profile.svg" => render::design::profile_svg(design).into_bytes(),
        "cam.step" => step::step_text(&part()?.part, &spec.name)
            .map_err(|e| encode("cam.step")(e.to_string()))?
            .into_bytes(),
        "cam.stl" => stl::stl_bytes(&part()?.mesh),
        "cam.dxf" => dxf::dxf_bytes(&part()?.part).map_err(encode("cam.dxf"))?,
        "drawing.svg" => drawing::drawing_svg(design, &part()?.part).into_bytes(),
        "cam.ngc" => program()?.text.clone().into_bytes(),
        "toolpath.svg" => {
            render::design::toolpath_svg(design, &part()?.part, &program()?.passes).into_bytes()
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
        .map(|n| Ok((n.to_string(), render_file(design, outputs, n)?)))
        .collect()
}

/// Writes the planned outputs of a design into `dir`; returns the paths written.
pub fn write_design(
    design: &Design,
    outputs: &Outputs,
    dir: &Path,
) -> Result<Vec<PathBuf>, ExportError> {
    let mut written = Vec::new();
    for (name, bytes) in design_files(design, outputs)? {
        let path = dir.join(&name);
        write_atomic(&path, &bytes)?;
        written.push(path);
    }
    Ok(written)
}
