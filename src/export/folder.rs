//! An output folder that always holds exactly one complete run.
//!
//! [`write_set`] writes the whole set into a fresh sibling folder, carries over what the user
//! keeps in the old folder (calibration logs, a `sweep/` folder: everything that is not one of
//! the run's own outputs), and then swaps the two folders in one step (`renameat2` with
//! `RENAME_EXCHANGE` on Linux). A reader, a killed run or a power cut sees the old set or the
//! new one, never a mix, and a refused part leaves no part files behind.
//!
//! The folder is locked for the whole run (an advisory lock on `.NAME.camspring.lock` beside
//! it, released by the kernel if the process dies), so two runs on one folder do not mix: the
//! second is refused. Leftovers of killed runs (staging folders) are cleaned up, and what they
//! carried is put back, by the next run on the same folder.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use super::ExportError;

/// Staging folders are named `.NAME` + this + a process id.
const STAGE_MARK: &str = ".camspring-stage-";

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> ExportError + '_ {
    move |source| ExportError::Write {
        path: path.to_path_buf(),
        source,
    }
}

/// Where the run goes: the folder (symbolic links to a folder are followed), its parent and
/// its name; refuses a path that exists and is not a folder.
fn resolve(dir: &Path) -> Result<(PathBuf, PathBuf, String), ExportError> {
    let dir = match fs::symlink_metadata(dir) {
        Ok(m) if m.file_type().is_symlink() => fs::canonicalize(dir).map_err(write_err(dir))?,
        _ => dir.to_path_buf(),
    };
    if let Ok(m) = fs::metadata(&dir) {
        if !m.is_dir() {
            return Err(ExportError::NotWritable {
                path: dir,
                why: "it exists and is not a folder".into(),
            });
        }
    }
    let absolute = if dir.is_absolute() {
        dir.clone()
    } else {
        std::env::current_dir().map_err(write_err(&dir))?.join(&dir)
    };
    let name = absolute
        .file_name()
        .filter(|n| *n != "." && *n != "..")
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| ExportError::NotWritable {
            path: dir.clone(),
            why: "an output folder needs a name of its own (not `.`, `..` or `/`)".into(),
        })?;
    // The folder is replaced as a whole: a shell standing in it would be left in a removed folder.
    if let (Ok(here), Ok(there)) = (
        std::env::current_dir().and_then(fs::canonicalize),
        fs::canonicalize(&absolute),
    ) {
        if here.starts_with(&there) {
            return Err(ExportError::NotWritable {
                path: dir.clone(),
                why: "it is (or holds) the current folder, and a run replaces its output folder \
                      as a whole; give a folder of its own, for example -o out/NAME"
                    .into(),
            });
        }
    }
    let parent = absolute
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("/"));
    Ok((absolute, parent, name))
}

/// Holds the folder's lock while it lives.
struct Lock {
    _file: File,
}

fn lock(parent: &Path, name: &str) -> Result<Lock, ExportError> {
    let path = parent.join(format!(".{name}.camspring.lock"));
    let file = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(write_err(&path))?;
    match file.try_lock() {
        Ok(()) => Ok(Lock { _file: file }),
        Err(fs::TryLockError::WouldBlock) => Err(ExportError::Busy {
            path: parent.join(name),
        }),
        Err(fs::TryLockError::Error(e)) => Err(write_err(&path)(e)),
    }
}

/// Moves what a killed run left in its staging folders back where it belongs, then removes
/// them. Anything that is not one of the run's own outputs and is missing from the folder was
/// carried over by the killed run and is put back.
fn recover(parent: &Path, name: &str, dir: &Path, owned: &[&str]) -> Result<(), ExportError> {
    let prefix = format!(".{name}{STAGE_MARK}");
    let Ok(entries) = fs::read_dir(parent) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let stage_name = entry.file_name().to_string_lossy().into_owned();
        if !stage_name.starts_with(&prefix) {
            continue;
        }
        let stage = entry.path();
        if !dir.exists() && stage_name.ends_with("-old") {
            // A swap without RENAME_EXCHANGE stopped between its two renames.
            fs::rename(&stage, dir).map_err(write_err(dir))?;
            continue;
        }
        if dir.is_dir() {
            for item in fs::read_dir(&stage).map_err(write_err(&stage))?.flatten() {
                let n = item.file_name();
                let target = dir.join(&n);
                let is_output = owned.iter().any(|o| n == **o);
                if !is_output && fs::symlink_metadata(&target).is_err() {
                    fs::rename(item.path(), &target).map_err(write_err(&target))?;
                }
            }
        }
        fs::remove_dir_all(&stage).map_err(write_err(&stage))?;
    }
    Ok(())
}

/// Carries an entry of the old folder into the new one: files as hard links (a copy where the
/// file system has none), symbolic links as links, folders by moving them.
fn carry(from: &Path, to: &Path) -> Result<(), ExportError> {
    let meta = fs::symlink_metadata(from).map_err(write_err(from))?;
    if meta.is_dir() {
        fs::rename(from, to).map_err(write_err(from))
    } else if meta.file_type().is_symlink() {
        let target = fs::read_link(from).map_err(write_err(from))?;
        symlink(&target, to).map_err(write_err(to))
    } else if fs::hard_link(from, to).is_err() {
        fs::copy(from, to).map(|_| ()).map_err(write_err(to))
    } else {
        Ok(())
    }
}

#[cfg(unix)]
fn symlink(target: &Path, link: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(target, link)
}

#[cfg(not(unix))]
fn symlink(target: &Path, link: &Path) -> std::io::Result<()> {
    fs::copy(target, link).map(|_| ())
}

/// Exchanges two folders in one step where the system can; otherwise by two renames, which
/// [`recover`] completes if interrupted.
fn exchange(stage: &Path, dir: &Path) -> Result<(), ExportError> {
    #[cfg(target_os = "linux")]
    {
        use std::ffi::CString;
        use std::os::unix::ffi::OsStrExt;
        let a =
            CString::new(stage.as_os_str().as_bytes()).map_err(|_| ExportError::NotWritable {
                path: stage.to_path_buf(),
                why: "the path holds a NUL byte".into(),
            })?;
        let b = CString::new(dir.as_os_str().as_bytes()).map_err(|_| ExportError::NotWritable {
            path: dir.to_path_buf(),
            why: "the path holds a NUL byte".into(),
        })?;
        // SAFETY: both pointers are valid NUL-terminated strings for the call's duration.
        let r = unsafe {
            libc::renameat2(
                libc::AT_FDCWD,
                a.as_ptr(),
                libc::AT_FDCWD,
                b.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        if r == 0 {
            return Ok(());
        }
        let err = std::io::Error::last_os_error();
        // Older kernels and some file systems do not exchange; fall back to two renames.
        if !matches!(err.raw_os_error(), Some(libc::EINVAL) | Some(libc::ENOSYS)) {
            return Err(write_err(dir)(err));
        }
    }
    let old = PathBuf::from(format!("{}-old", stage.display()));
    fs::rename(dir, &old).map_err(write_err(dir))?;
    fs::rename(stage, dir).map_err(write_err(dir))?;
    fs::rename(&old, stage).map_err(write_err(stage))
}

fn sync_dir(dir: &Path) {
    // Best effort: not every platform can open a folder to sync it.
    if let Ok(f) = File::open(dir) {
        let _ = f.sync_all();
    }
}

/// Writes `files` (name, bytes) as the new content of `dir`, replacing the previous run as a
/// whole. `owned` lists every name a run of this kind can produce: such files in the old folder
/// belong to the old run and are dropped; everything else there is kept. Returns the paths.
pub fn write_set(
    dir: &Path,
    files: &[(String, Vec<u8>)],
    owned: &[&str],
) -> Result<Vec<PathBuf>, ExportError> {
    let given = dir.to_path_buf();
    let (dir, parent, name) = resolve(dir)?;
    fs::create_dir_all(&parent).map_err(write_err(&parent))?;
    let _lock = lock(&parent, &name)?;
    recover(&parent, &name, &dir, owned)?;
    let stage = parent.join(format!(".{name}{STAGE_MARK}{}", std::process::id()));
    if stage.exists() {
        fs::remove_dir_all(&stage).map_err(write_err(&stage))?;
    }
    fs::create_dir(&stage).map_err(write_err(&stage))?;
    for (file, bytes) in files {
        let path = stage.join(file);
        let mut f = File::create(&path).map_err(write_err(&dir.join(file)))?;
        f.write_all(bytes).map_err(write_err(&dir.join(file)))?;
        f.sync_all().map_err(write_err(&dir.join(file)))?;
    }
    if dir.is_dir() {
        for entry in fs::read_dir(&dir).map_err(write_err(&dir))?.flatten() {
            let n = entry.file_name();
            if !owned.iter().any(|o| n == **o) {
                carry(&entry.path(), &stage.join(&n))?;
            }
        }
        sync_dir(&stage);
        exchange(&stage, &dir)?;
        sync_dir(&parent);
        // The staging name now holds the previous run; what it carried is in the new folder.
        fs::remove_dir_all(&stage).map_err(write_err(&stage))?;
    } else {
        sync_dir(&stage);
        fs::rename(&stage, &dir).map_err(write_err(&dir))?;
        sync_dir(&parent);
    }
    // The paths as the user named the folder.
    Ok(files.iter().map(|(n, _)| given.join(n)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(names: &[&str], tag: &str) -> Vec<(String, Vec<u8>)> {
        names
            .iter()
            .map(|n| (n.to_string(), format!("{tag} {n}").into_bytes()))
            .collect()
    }

    #[test]
    fn a_smaller_run_leaves_no_file_of_the_larger_one_and_keeps_the_users_files() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("out");
        let owned = ["a.json", "b.step", "c.ngc"];
        write_set(&dir, &set(&owned, "one"), &owned).unwrap();
        fs::write(dir.join("calib.csv"), "mine").unwrap();
        fs::create_dir(dir.join("sweep")).unwrap();
        fs::write(dir.join("sweep/sweep.csv"), "also mine").unwrap();
        write_set(&dir, &set(&["a.json"], "two"), &owned).unwrap();
        let mut names: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["a.json", "calib.csv", "sweep"]);
        assert_eq!(
            fs::read_to_string(dir.join("a.json")).unwrap(),
            "two a.json"
        );
        assert_eq!(fs::read_to_string(dir.join("calib.csv")).unwrap(), "mine");
        assert_eq!(
            fs::read_to_string(dir.join("sweep/sweep.csv")).unwrap(),
            "also mine"
        );
        // No staging folder is left beside it.
        let leftovers: Vec<_> = fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(STAGE_MARK))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
    }

    #[test]
    fn a_killed_runs_staging_folder_is_cleaned_and_its_carried_folder_put_back() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("out");
        let owned = ["a.json"];
        write_set(&dir, &set(&owned, "one"), &owned).unwrap();
        // A run killed after moving the user's folder into its staging folder.
        let stage = tmp.path().join(format!(".out{STAGE_MARK}999999"));
        fs::create_dir_all(stage.join("sweep")).unwrap();
        fs::write(stage.join("sweep/s.csv"), "kept").unwrap();
        fs::write(stage.join("a.json"), "half").unwrap();
        write_set(&dir, &set(&owned, "two"), &owned).unwrap();
        assert!(!stage.exists());
        assert_eq!(fs::read_to_string(dir.join("sweep/s.csv")).unwrap(), "kept");
        assert_eq!(
            fs::read_to_string(dir.join("a.json")).unwrap(),
            "two a.json"
        );
    }

    #[test]
    fn a_second_run_on_a_locked_folder_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("out");
        let _held = lock(tmp.path(), "out").unwrap();
        let e = write_set(&dir, &set(&["a"], "x"), &["a"]).unwrap_err();
        assert!(matches!(e, ExportError::Busy { .. }), "{e}");
        assert!(e.to_string().contains("another camspring run"), "{e}");
    }

    #[test]
    fn a_file_where_the_folder_should_be_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("out");
        fs::write(&file, "not a folder").unwrap();
        let e = write_set(&file, &set(&["a"], "x"), &["a"]).unwrap_err();
        assert!(e.to_string().contains("not a folder"), "{e}");
        assert_eq!(fs::read_to_string(&file).unwrap(), "not a folder");
    }
}
