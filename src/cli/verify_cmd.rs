//! `prtbake verify`: bake analytic scenes and compare with closed forms.

use super::Outcome;
use crate::verify::{self, VerifyParams};

/// Runs every check; `Outcome::CheckFailed` when any fails.
pub fn run(params: VerifyParams, threads: usize, as_json: bool) -> anyhow::Result<Outcome> {
    let checks = super::with_threads(threads, || verify::verify_all(params))??;
    if as_json {
        super::print_json(&serde_json::to_value(&checks)?)?;
    } else {
        print!("{}", verify::format_table(&checks));
    }
    let failed = checks.iter().filter(|c| !c.passed).count();
    if !as_json {
        println!("{} passed, {} failed", checks.len() - failed, failed);
    }
    Ok(if failed == 0 { Outcome::Ok } else { Outcome::CheckFailed })
}
