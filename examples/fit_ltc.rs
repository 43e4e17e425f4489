//! Fits the GGX LTC table and writes `shared/src/ltc_table.rs`, or checks the committed table.
//!
//! ```text
//! cargo run --release --no-default-features --example fit_ltc -- --out shared/src/ltc_table.rs
//! cargo run --release --no-default-features --example fit_ltc -- --check
//! ```
//!
//! The fit itself is `raywave::ltc_fit` (host crate); this binary prints progress and the fit
//! error per roughness row, and writes the file atomically (a temporary file in the same folder,
//! then a rename); an `--out` it cannot write fails before the fit. `--check` re-fits a spread of cells from the committed table's warm starts and
//! compares them with the committed values; it exits with status 1 if any differs by more than the
//! stated tolerances.

use clap::Parser;
use raywave::ltc_fit::{self, FitConfig, CHECK_L1_TOLERANCE, CHECK_VALUE_TOLERANCE, LTC_SIZE};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(about = "Fit the GGX LTC table (raywave::ltc_fit) or check the committed one")]
struct Args {
    /// Where to write the generated Rust source (not with `--check`, which writes nothing).
    #[arg(long, default_value = "shared/src/ltc_table.rs", conflicts_with = "check")]
    out: PathBuf,
    /// Re-fit a sample of cells and compare with the committed table instead of fitting it all.
    #[arg(long)]
    check: bool,
    /// With `--check`: this many more cells, spread over the table, besides the fixed 12 (at most
    /// the table's other 4084: then every cell is checked once). Only with `--check`: without it
    /// the command would start the full fit.
    #[arg(long, default_value_t = 0, requires = "check")]
    extra: usize,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let cfg = FitConfig::default();
    if args.check {
        return check(&cfg, args.extra);
    }
    // Before the fit, which takes most of an hour: a path that cannot be written fails now.
    if let Err(e) = check_writable(&args.out) {
        eprintln!("error: cannot write {}: {e}", args.out.display());
        return ExitCode::FAILURE;
    }
    eprintln!("fitting {LTC_SIZE}×{LTC_SIZE} LTC cells with {cfg:?}");
    let start = Instant::now();
    let table = ltc_fit::fit_table(&cfg, &|diagonals| {
        let total = 2 * LTC_SIZE - 1;
        eprintln!("  {diagonals}/{total} anti-diagonals done ({:.1} s)", start.elapsed().as_secs_f64());
    });
    let secs = start.elapsed().as_secs_f64();
    let evals: usize = table.cells.iter().map(|c| c.evals).sum();
    println!("fit: {secs:.1} s, {evals} objective evaluations");
    print_errors(&table);
    let source = ltc_fit::table_source(&table);
    match write_atomically(&args.out, source.as_bytes()) {
        Ok(()) => {
            println!("wrote {}", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: cannot write {}: {e}", args.out.display());
            ExitCode::FAILURE
        }
    }
}

/// Prints the relative L1 error `∫|f·cos − g|/∫f·cos` per roughness row (median and max over θ).
fn print_errors(table: &ltc_fit::LtcTable) {
    println!("relative L1 error of the two-lobe LTC vs the GGX lobe, ∫|f·cos − g| / ∫f·cos, per roughness row:");
    println!("{:>3} {:>6} {:>9} {:>8} {:>8} {:>8} {:>6}", "row", "r", "alpha", "median", "p90", "max", "at col");
    for a in 0..LTC_SIZE {
        let (median, p90, max) = ltc_fit::row_error_stats(table, a);
        let worst =
            (0..LTC_SIZE).max_by(|&x, &y| table.cell(a, x).rel_l1_error.total_cmp(&table.cell(a, y).rel_l1_error));
        println!(
            "{a:>3} {:>6.3} {:>9.2e} {median:>8.4} {p90:>8.4} {max:>8.4} {:>6}",
            a as f64 / (LTC_SIZE - 1) as f64,
            ltc_fit::cell_alpha(a),
            worst.unwrap_or(0)
        );
    }
    let (median, _, max) = ltc_fit::error_percentiles(table.cells.iter().map(|c| c.rel_l1_error).collect());
    println!("all cells: median {median:.4}, max {max:.4}");
    // Without the most grazing views (cos θ < 0.21, θ > 78°), where GGX lobes are least LTC-like.
    let inner = table.cells.iter().filter(|c| c.t <= 56).map(|c| c.rel_l1_error).collect();
    let (median, p90, max) = ltc_fit::error_percentiles(inner);
    println!("cells with cos θ ≥ 0.2099 (col ≤ 56): median {median:.4}, p90 {p90:.4}, max {max:.4}");
}

fn check(cfg: &FitConfig, extra: usize) -> ExitCode {
    let most = LTC_SIZE * LTC_SIZE - ltc_fit::CHECK_CELLS.len();
    if extra > most {
        eprintln!("error: --extra {extra} exceeds the table's other {most} cells");
        return ExitCode::FAILURE;
    }
    let start = Instant::now();
    let mut cells = ltc_fit::CHECK_CELLS.to_vec();
    cells.extend(ltc_fit::spread_cells(extra));
    let checks = ltc_fit::check_cells(&cells, &ltc_fit::PackedTable::committed(), cfg);
    println!("{:>3} {:>3} {:>10} {:>10} {:>10} {:>10}", "row", "col", "L1 dist", "d mag", "d fresnel", "d sphere");
    let mut ok = true;
    for c in &checks {
        println!(
            "{:>3} {:>3} {:>10.2e} {:>10.2e} {:>10.2e} {:>10.2e}",
            c.refit.a, c.refit.t, c.l1_distance, c.magnitude_diff, c.fresnel_diff, c.sphere_diff
        );
        ok &= c.l1_distance <= CHECK_L1_TOLERANCE
            && c.magnitude_diff <= CHECK_VALUE_TOLERANCE
            && c.fresnel_diff <= CHECK_VALUE_TOLERANCE
            && c.sphere_diff <= CHECK_VALUE_TOLERANCE;
    }
    println!("checked {} cells in {:.1} s", checks.len(), start.elapsed().as_secs_f64());
    if ok {
        println!("committed table matches (L1 ≤ {CHECK_L1_TOLERANCE}, values ≤ {CHECK_VALUE_TOLERANCE:e})");
        ExitCode::SUCCESS
    } else {
        println!("committed table DIFFERS from a re-fit: regenerate it");
        ExitCode::FAILURE
    }
}

/// Fails where `path` cannot become the table's file: it names a directory (or ends in a
/// separator), or its folder is missing or not writable — probed with a temporary file there,
/// removed at once (one held through the fit would stay behind if the fit is interrupted).
fn check_writable(path: &Path) -> std::io::Result<()> {
    if path.is_dir() || path.as_os_str().to_string_lossy().ends_with(std::path::MAIN_SEPARATOR) {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "it names a directory"));
    }
    tempfile::Builder::new().prefix(".fit_ltc-").tempfile_in(folder_of(path)).map(drop)
}

/// The folder `path` lies in (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Writes `bytes` to a temporary file beside `path`, syncs it, then renames it over `path`. On any
/// error the temporary file is deleted (dropping it, or `persist`'s error, does), so a failed
/// write leaves `path` as it was and nothing beside it.
fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = tempfile::Builder::new().prefix(".fit_ltc-").tempfile_in(folder_of(path))?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map(drop).map_err(|e| e.error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extra_needs_check_and_out_conflicts_with_it() {
        let parse = |args: &[&str]| Args::try_parse_from(std::iter::once("fit_ltc").chain(args.iter().copied()));
        // `--extra` without `--check` would start the full fit and overwrite the table.
        assert!(parse(&["--extra", "100"]).is_err());
        // `--check` writes nothing: an `--out` beside it would be ignored.
        assert!(parse(&["--check", "--out", "x.rs"]).is_err());
        let check = parse(&["--check", "--extra", "3"]).expect("--check --extra");
        assert!(check.check && check.extra == 3);
        let fit = parse(&["--out", "x.rs"]).expect("--out");
        assert!(!fit.check && fit.out == Path::new("x.rs"));
        assert_eq!(parse(&[]).expect("no arguments").out, Path::new("shared/src/ltc_table.rs"));
    }

    #[test]
    fn a_failed_write_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        // A directory where the file should go: the rename over it fails after the write.
        let blocked = dir.path().join("blocked.rs");
        std::fs::create_dir(&blocked).unwrap();
        assert!(write_atomically(&blocked, b"table").is_err());
        let names =
            |dir: &Path| -> Vec<_> { std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name()).collect() };
        assert_eq!(names(dir.path()), ["blocked.rs"]);

        let out = dir.path().join("table.rs");
        write_atomically(&out, b"table").unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"table");
        let mut written = names(dir.path());
        written.sort();
        assert_eq!(written, ["blocked.rs", "table.rs"]);
    }
}
