//! Output files: one policy for every command that writes a file.
//!
//! * **Never an input.** [`check_outputs`] refuses an output path that is one of the
//!   command's inputs (compared after resolving `.`/`..` and symbolic links, and by inode
//!   for hard links) or that two outputs share. Commands call it before any work.
//! * **Whole or not at all.** [`write`] writes a temporary file beside the destination,
//!   flushes and syncs it, then renames it over the destination. On an error the temporary
//!   file is removed (a drop guard) and the destination is untouched; on Ctrl-C (SIGINT),
//!   SIGTERM or SIGHUP the handler that `main` installs with [`install_interrupt_cleanup`]
//!   removes every temporary file still being written, prints `error: interrupted` and exits
//!   with 128 + the signal number.
//! * **Permissions kept.** Replacing an existing file keeps its permission bits; a new file is
//!   created 0644.
//! * **Symbolic links are written through.** When the destination is a symbolic link, the
//!   file it points to is replaced (the temporary file sits beside that target) and the link
//!   stays a link; a link to a missing file is refused.
//! * **Devices and pipes are written in place.** `-o /dev/null` or a named pipe is opened and
//!   written, never renamed over.
//! * **Missing folders: below the current directory, or one level elsewhere.** The missing
//!   folders of a relative output path that stays below the current directory (no `..`) are
//!   created (`--report out/compare`); elsewhere only the output's own folder is, inside one
//!   that exists and not at the root (`--report /tmp/run/report`). A `note: created directory
//!   DIR` line on stderr says so once the file is written; when the write fails, the folders
//!   are removed again. `-o /nonexistent/x.csv` or `-o /tmp/typo/deeper/x.csv` is refused,
//!   naming the folder, before any work ([`check_outputs`]): such paths are typos far more
//!   often than wishes.
use anyhow::{anyhow, bail, Context, Result};
use std::io::Write;
use std::path::{Component, Path, PathBuf};

/// `path` made absolute and resolved as far as it exists: symbolic links and `..` of the
/// existing part are resolved (`canonicalize`), the missing rest is appended as given.
fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .unwrap_or_else(|_| PathBuf::from("/"))
            .join(path)
    };
    // Canonicalise the longest existing ancestor, then append the rest lexically.
    let mut rest = Vec::new();
    let mut base = abs.as_path();
    loop {
        if let Ok(c) = std::fs::canonicalize(base) {
            let mut out = c;
            for part in rest.iter().rev() {
                match part {
                    Component::ParentDir => {
                        out.pop();
                    }
                    Component::CurDir => {}
                    c => out.push(c.as_os_str()),
                }
            }
            return out;
        }
        match (base.parent(), base.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                base = parent;
            }
            _ => return abs,
        }
    }
}

/// True when `a` and `b` name the same file (same resolved path, or same inode).
pub fn same_file(a: &Path, b: &Path) -> bool {
    if resolve(a) == resolve(b) {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// Refuse an output path that is also one of the command's inputs, or that two outputs
/// share; call before any work. The message names the path.
pub fn check_outputs(outputs: &[&Path], inputs: &[&Path]) -> Result<()> {
    for (k, out) in outputs.iter().enumerate() {
        if let Some(inp) = inputs.iter().find(|i| same_file(out, i)) {
            bail!(
                "{}: the output file is also an input ({}) and would be overwritten; choose \
                 another output path",
                crate::log::echo_path(out),
                crate::log::echo_path(inp)
            );
        }
        if let Some(other) = outputs[..k].iter().find(|o| same_file(out, o)) {
            bail!(
                "{}: two outputs of this command are the same file ({}); give each its own path",
                crate::log::echo_path(out),
                crate::log::echo_path(other)
            );
        }
        check_shape(out)?;
        // The folder policy too, before any work rather than at the write.
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            folder_policy(out, &missing_dirs(dir))?;
        }
    }
    Ok(())
}

/// An output path must name a file: not an existing directory, nor a name ending in `/`, nor a
/// file below something that is not a folder.
fn check_shape(out: &Path) -> Result<()> {
    let p = crate::log::echo_path(out);
    if out.is_dir() || out.as_os_str().as_encoded_bytes().ends_with(b"/") {
        bail!("{p}: is a directory name; give a file name for the output");
    }
    // The nearest existing ancestor must be a folder (`--report data.csv` writes below it).
    if let Some(above) = out
        .ancestors()
        .skip(1)
        .find(|a| !a.as_os_str().is_empty() && std::fs::symlink_metadata(a).is_ok())
    {
        if !above.is_dir() {
            bail!(
                "{p}: {} is a file, not a folder; give another output path",
                crate::log::echo_path(above)
            );
        }
    }
    Ok(())
}

/// The module's folder policy for output `path` whose missing folders are `missing`
/// (outermost first): any below the current directory, else at most one and not at the root.
fn folder_policy(path: &Path, missing: &[PathBuf]) -> Result<()> {
    let Some(first) = missing.first() else {
        return Ok(());
    };
    let below_cwd = path
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    if below_cwd {
        return Ok(());
    }
    let parent = resolve(first).parent().map(Path::to_path_buf);
    if missing.len() > 1 || parent.is_none_or(|p| p.parent().is_none()) {
        bail!(
            "{}: folder {} does not exist; create it first (outside the current directory \
             motorid creates only the output's own folder, inside one that exists, not at the \
             root)",
            crate::log::echo_path(path),
            crate::log::echo_path(first)
        );
    }
    Ok(())
}

/// The directories `create_dir_all(dir)` would create, outermost first.
fn missing_dirs(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut d = Some(dir);
    while let Some(p) = d {
        if p.as_os_str().is_empty() || p.exists() {
            break;
        }
        out.push(p.to_path_buf());
        d = p.parent();
    }
    out.reverse();
    out
}

/// Write `bytes` to `path` atomically (the module's policy: temporary file beside the
/// destination, then rename; permissions kept; symbolic links written through; missing
/// folders created and announced). On any error `path` is untouched and nothing is left
/// behind.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    let p = crate::log::echo_path(path);
    // A symbolic link: write through to its target.
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path).map_err(|_| {
            anyhow!("{p}: is a symbolic link to a missing file; refusing to write through it")
        })?,
        _ => path.to_path_buf(),
    };
    let existing = std::fs::metadata(&target).ok();
    check_shape(path)?;
    // A device, pipe or socket (`-o /dev/null`, `-o /dev/stdout`): written in place, never
    // replaced by a regular file.
    if existing.as_ref().is_some_and(|m| !m.is_file()) {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open(&target)
            .with_context(|| format!("{p}: cannot open for writing"))?;
        return f
            .write_all(bytes)
            .and_then(|()| f.flush())
            .with_context(|| format!("{p}: cannot write"));
    }
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let created = missing_dirs(&dir);
    folder_policy(path, &created)?;
    if !created.is_empty() {
        std::fs::create_dir_all(&dir).with_context(|| {
            format!(
                "{p}: cannot create directory {}",
                crate::log::echo_path(&dir)
            )
        })?;
    }
    let result = write_in(&dir, &target, existing.as_ref(), bytes);
    match result {
        Ok(()) => {
            if let Some(first) = created.first() {
                eprintln!("note: created directory {}", crate::log::echo_path(first));
            }
            Ok(())
        }
        Err(e) => {
            for d in created.iter().rev() {
                let _ = std::fs::remove_dir(d);
            }
            Err(e.context(format!("{p}: cannot write")))
        }
    }
}

fn write_in(
    dir: &Path,
    target: &Path,
    existing: Option<&std::fs::Metadata>,
    bytes: &[u8],
) -> Result<()> {
    let mut tmp = tempfile::Builder::new()
        .prefix(".motorid-")
        .suffix(".tmp")
        .tempfile_in(dir)
        // The error's kind alone: its text names the temporary file, not the user's.
        .map_err(|e| {
            anyhow!(
                "cannot create a file in {}: {}",
                crate::log::echo_path(dir),
                std::io::Error::from(e.kind())
            )
        })?;
    // Removed by the handler on Ctrl-C; by `tmp`'s own drop on an error.
    let _guard = interrupt::register(tmp.path());
    // Temporary files are created 0600: keep the replaced file's bits, else the usual 0644.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let perms = match existing {
            Some(m) => m.permissions(),
            None => std::fs::Permissions::from_mode(0o644),
        };
        tmp.as_file().set_permissions(perms)?;
    }
    #[cfg(not(unix))]
    let _ = existing;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(target).map_err(|e| e.error)?;
    Ok(())
}

/// Write a text file atomically.
pub fn write_str(path: &Path, text: &str) -> Result<()> {
    write(path, text.as_bytes())
}

/// Install the SIGINT/SIGTERM/SIGHUP handler that removes the temporary files of writes in
/// progress, prints `error: interrupted` and exits (128 + signal). Called once by `main`.
pub fn install_interrupt_cleanup() {
    interrupt::install();
}

#[cfg(unix)]
mod interrupt {
    //! The handler only uses async-signal-safe calls (`unlink`, `write`, `_exit`) on paths
    //! kept as C strings in a fixed table of atomic pointers.
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    use std::path::Path;
    use std::ptr::null_mut;
    use std::sync::atomic::{AtomicPtr, Ordering};

    const SLOTS: usize = 32;
    static TEMPS: [AtomicPtr<libc::c_char>; SLOTS] = [const { AtomicPtr::new(null_mut()) }; SLOTS];

    extern "C" fn on_signal(sig: libc::c_int) {
        for slot in &TEMPS {
            let p = slot.swap(null_mut(), Ordering::SeqCst);
            if !p.is_null() {
                // SAFETY: `p` came from `CString::into_raw` and nobody else owns it now.
                unsafe {
                    libc::unlink(p);
                }
            }
        }
        let msg = b"error: interrupted\n";
        // SAFETY: write(2) and _exit(2) are async-signal-safe.
        unsafe {
            libc::write(2, msg.as_ptr().cast(), msg.len());
            libc::_exit(128 + sig);
        }
    }

    pub fn install() {
        let handler = on_signal as extern "C" fn(libc::c_int);
        for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            // SAFETY: installing a handler that only makes async-signal-safe calls.
            unsafe {
                libc::signal(sig, handler as libc::sighandler_t);
            }
        }
    }

    /// A temporary path registered for removal on a signal; unregistered on drop.
    pub struct Registered(Option<usize>);

    pub fn register(path: &Path) -> Registered {
        let Ok(c) = CString::new(path.as_os_str().as_bytes()) else {
            return Registered(None);
        };
        let raw = c.into_raw();
        for (k, slot) in TEMPS.iter().enumerate() {
            if slot
                .compare_exchange(null_mut(), raw, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
            {
                return Registered(Some(k));
            }
        }
        // SAFETY: `raw` was not stored anywhere.
        drop(unsafe { CString::from_raw(raw) });
        Registered(None)
    }

    impl Drop for Registered {
        fn drop(&mut self) {
            if let Some(k) = self.0 {
                let p = TEMPS[k].swap(null_mut(), Ordering::SeqCst);
                if !p.is_null() {
                    // SAFETY: from `CString::into_raw` in `register`; the handler did not take it.
                    drop(unsafe { CString::from_raw(p) });
                }
            }
        }
    }
}

#[cfg(not(unix))]
mod interrupt {
    pub fn install() {}
    pub struct Registered;
    pub fn register(_: &std::path::Path) -> Registered {
        Registered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(unix)]
    fn a_device_is_written_in_place_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        write(Path::new("/dev/null"), b"discarded").unwrap();
        let m = std::fs::metadata("/dev/null").unwrap();
        assert!(
            m.file_type().is_char_device(),
            "/dev/null is still a device"
        );
    }

    #[test]
    fn outputs_that_are_inputs_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a.csv");
        std::fs::write(&a, "x").unwrap();
        let dotted = d.path().join("sub").join("..").join("a.csv");
        let e = check_outputs(&[&dotted], &[&a]).unwrap_err().to_string();
        assert!(e.contains("also an input"), "{e}");
        let b = d.path().join("b.csv");
        assert!(check_outputs(&[&b], &[&a]).is_ok());
        assert!(check_outputs(&[&b, &b], &[&a]).is_err());
        #[cfg(unix)]
        {
            let l = d.path().join("link.csv");
            std::os::unix::fs::symlink(&a, &l).unwrap();
            assert!(check_outputs(&[&l], &[&a]).is_err());
            let h = d.path().join("hard.csv");
            std::fs::hard_link(&a, &h).unwrap();
            assert!(check_outputs(&[&h], &[&a]).is_err());
        }
    }

    #[cfg(unix)]
    #[test]
    fn permissions_kept_symlinks_written_through_nothing_left_behind() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("f.txt");
        std::fs::write(&f, "old").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
        write_str(&f, "new").unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "new");
        let mode = std::fs::metadata(&f).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        let l = d.path().join("l.txt");
        std::os::unix::fs::symlink(&f, &l).unwrap();
        write_str(&l, "through").unwrap();
        assert!(std::fs::symlink_metadata(&l)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "through");
        let dangling = d.path().join("dangling");
        std::os::unix::fs::symlink(d.path().join("missing"), &dangling).unwrap();
        assert!(write_str(&dangling, "x").is_err());
        write_str(&d.path().join("new/x.txt"), "x").unwrap();
        assert!(d.path().join("new/x.txt").is_file());
        let e = write_str(&d.path().join("a/b/x.txt"), "x").unwrap_err();
        assert!(format!("{e:#}").contains("does not exist"), "{e:#}");
        assert!(!d.path().join("a").exists());
        assert!(write_str(d.path(), "x").is_err());
        let names: Vec<String> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(!names.iter().any(|n| n.ends_with(".tmp")), "{names:?}");
    }
}
