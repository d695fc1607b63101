//! Skips that say so. [`skip`] prints `skipped: <test>: <reason>` (seen with `--nocapture`) and
//! appends the same line to the file named by `MESOFLOW_SKIP_LOG`, which `scripts/test` sets,
//! empties before the run and sums up after it ("N skipped", each reason listed), because
//! `cargo test` itself reports a test that returned early as `ok`.
//! [`skip_unless_required`] fails instead where a `MESOFLOW_REQUIRE_*` variable is `1` (CI).

use std::io::Write;

/// The running test's name: libtest names each test's thread after it.
fn test_name() -> String {
    std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string()
}

/// Records that the running test (or part of it) did not run, and why.
pub fn skip(reason: &str) {
    // One line a skip, so that the log counts by lines (GPU errors span several).
    let reason = reason.split_whitespace().collect::<Vec<_>>().join(" ");
    let line = format!("skipped: {}: {reason}", test_name());
    eprintln!("{line}");
    if let Some(path) = std::env::var_os("MESOFLOW_SKIP_LOG") {
        let appended = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .and_then(|mut f| writeln!(f, "{line}"));
        if let Err(e) = appended {
            eprintln!("cannot record the skip in {}: {e}", path.to_string_lossy());
        }
    }
}

/// Whether the environment variable `var` is `1`: what is missing is then required.
pub fn required(var: &str) -> bool {
    std::env::var(var).as_deref() == Ok("1")
}

/// [`skip`], unless `var` is `1`, where the test fails with the reason.
pub fn skip_unless_required(var: &str, reason: &str) {
    assert!(!required(var), "{var}=1 but {reason}");
    skip(reason);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_skip_is_logged_with_the_test_s_name() {
        let dir = std::env::temp_dir().join(format!("mesoflow-skip-{}", std::process::id()));
        let _ = std::fs::remove_file(&dir);
        // The variable is read at the skip; this test is the crate's only one that sets it.
        std::env::set_var("MESOFLOW_SKIP_LOG", &dir);
        skip("no adapter");
        let text = std::fs::read_to_string(&dir).unwrap();
        let _ = std::fs::remove_file(&dir);
        assert!(
            text.contains("a_skip_is_logged_with_the_test_s_name: no adapter"),
            "{text}"
        );
    }

    #[test]
    #[should_panic(expected = "MESOFLOW_TESTKIT_REQUIRED=1 but nothing to run against")]
    fn a_required_skip_fails() {
        std::env::set_var("MESOFLOW_TESTKIT_REQUIRED", "1");
        skip_unless_required("MESOFLOW_TESTKIT_REQUIRED", "nothing to run against");
    }
}
