//! Measured data sets nobody on this team recorded, read through the generic tools:
//! the EMPS benchmark ([`emps`]), the TRO2021 screw drives ([`screw_drives`]) and the
//! OmniRobot DC motors ([`omni_dc`]). The data live in `../shared/data` beside the repository
//! (see its README.md for origins and licences); nothing is copied into the repository.
pub mod butterworth;
pub mod emps;
pub mod emps_loop;
pub mod omni_dc;
pub mod plots;
pub mod screw_drives;
pub mod static_curve;
pub mod table_csv;

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The data directory: `dir` if given, else `../shared/data` relative to the repository root
/// (the first ancestor of the current directory, or else of the `xtask` executable, that has
/// `../shared/data/README.md`).
pub fn locate(dir: Option<&Path>) -> Result<PathBuf> {
    if let Some(d) = dir {
        if !d.is_dir() {
            bail!("{}: no such data directory", d.display());
        }
        return Ok(d.to_path_buf());
    }
    let starts = [std::env::current_dir().ok(), std::env::current_exe().ok()];
    for start in starts.iter().flatten() {
        for a in start.ancestors() {
            let c = a.join("..").join("shared").join("data");
            if c.join("README.md").is_file() {
                return Ok(c);
            }
        }
    }
    bail!(
        "../shared/data not found beside the repository; pass --data DIR (the folder that holds \
         EMPS/, TRO2021_screw_drives/ and OmniRobot_DC_motors/)"
    )
}
