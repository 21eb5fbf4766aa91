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

/// The bytes of every file the plan lists, in writing order: `design.json` last, so that its
/// presence with this run's content marks a complete set.
pub fn design_files(
    design: &Design,
    outputs: &Outputs,
) -> Result<Vec<(&'static str, Vec<u8>)>, ExportError> {
    let summary = &outputs.summary;
    let json =
        serde_json::to_vec_pretty(summary).map_err(|e| encode("design.json")(e.to_string()))?;
    let force = render::design::force_svg(design);
    let profile = render::design::profile_svg(design);
    let report = render::html::report_html(design, summary, &force, &profile);
    let csv =
        render::design::profile_csv(design).map_err(|e| encode("profile.csv")(e.to_string()))?;
    let mut files: Vec<(&'static str, Vec<u8>)> = vec![
        ("profile.csv", csv),
        ("force.svg", force.into_bytes()),
        ("profile.svg", profile.into_bytes()),
    ];
    if let Some(p) = &outputs.part {
        let spec = &design.spec;
        let step =
            step::step_text(&p.part, &spec.name).map_err(|e| encode("cam.step")(e.to_string()))?;
        files.push(("cam.step", step.into_bytes()));
        files.push(("cam.stl", stl::stl_bytes(&p.mesh)));
        files.push((
            "cam.dxf",
            dxf::dxf_bytes(&p.part).map_err(encode("cam.dxf"))?,
        ));
        files.push((
            "drawing.svg",
            drawing::drawing_svg(design, &p.part).into_bytes(),
        ));
        if let Some(program) = &outputs.program {
            files.push(("cam.ngc", program.text.clone().into_bytes()));
            let svg = render::design::toolpath_svg(design, &p.part, &program.passes);
            files.push(("toolpath.svg", svg.into_bytes()));
        }
    }
    files.push(("report.html", report.into_bytes()));
    files.push(("design.json", json));
    debug_assert_eq!(files.len(), summary.outputs.len());
    Ok(files)
}

/// Writes the planned outputs of a design into `dir`; returns the paths written.
pub fn write_design(
    design: &Design,
    outputs: &Outputs,
    dir: &Path,
) -> Result<Vec<PathBuf>, ExportError> {
    let mut written = Vec::new();
    for (name, bytes) in design_files(design, outputs)? {
        let path = dir.join(name);
        write_atomic(&path, &bytes)?;
        written.push(path);
    }
    Ok(written)
}
