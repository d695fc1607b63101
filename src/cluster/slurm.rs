//! The three Slurm commands the driver uses, and nothing else of Slurm: `sbatch` to submit,
//! one `squeue` per poll for every job of the user, `scancel`. No accounting database is needed.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

fn run(cmd: &mut Command, what: &str) -> anyhow::Result<String> {
    let out = cmd
        .output()
        .map_err(|e| anyhow::anyhow!("{what}: cannot run it ({e}); is Slurm installed here?"))?;
    if !out.status.success() {
        anyhow::bail!(
            "{what} failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Splits `--sbatch-args` as a shell would, for the simple cases (spaces, single and double
/// quotes), without running a shell.
pub fn words(text: &str) -> Vec<String> {
    let (mut out, mut cur, mut quote, mut any) = (Vec::new(), String::new(), None, false);
    for ch in text.chars() {
        match (quote, ch) {
            (None, '\'' | '"') => {
                quote = Some(ch);
                any = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if any {
                    out.push(std::mem::take(&mut cur));
                    any = false;
                }
            }
            (_, c) => {
                cur.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(cur);
    }
    out
}

fn quoted(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// Submits `argv` as a job; returns its id.
pub fn sbatch(
    name: &str,
    log: &Path,
    extra: &[String],
    env: &[(&str, String)],
    argv: &[String],
) -> anyhow::Result<String> {
    let mut cmd = Command::new("sbatch");
    cmd.arg("--parsable")
        .arg(format!("--job-name={name}"))
        .arg(format!("--output={}", log.display()))
        .args(extra);
    let mut export = String::from("--export=ALL");
    for (k, v) in env {
        export.push_str(&format!(",{k}={v}"));
    }
    cmd.arg(export);
    let wrap: Vec<String> = argv.iter().map(|a| quoted(a)).collect();
    cmd.arg("--wrap").arg(wrap.join(" "));
    let out = run(&mut cmd, "sbatch")?;
    let id = out
        .trim()
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_string();
    if id.is_empty() {
        anyhow::bail!("sbatch printed no job id");
    }
    Ok(id)
}

/// Every job of this user that Slurm still knows as pending or running, with its state.
pub fn queue() -> anyhow::Result<BTreeMap<String, String>> {
    let out = run(
        Command::new("squeue").args(["-h", "--me", "-o", "%i %T"]),
        "squeue",
    )?;
    Ok(out
        .lines()
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            Some((it.next()?.to_string(), it.next()?.to_string()))
        })
        // A job that ends with a failure passes through these on its way out of the queue.
        .filter(|(_, state)| {
            !matches!(
                state.as_str(),
                "FAILED" | "NODE_FAIL" | "CANCELLED" | "TIMEOUT" | "BOOT_FAIL" | "OUT_OF_MEMORY"
            )
        })
        .collect())
}

pub fn scancel(jobs: &[String]) -> anyhow::Result<()> {
    if jobs.is_empty() {
        return Ok(());
    }
    run(Command::new("scancel").args(jobs), "scancel").map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sbatch_args_split_like_a_shell() {
        assert_eq!(
            words("--partition gpu --gres=gpu:1  --comment 'two words' \"x y\""),
            vec![
                "--partition",
                "gpu",
                "--gres=gpu:1",
                "--comment",
                "two words",
                "x y"
            ]
        );
        assert!(words("   ").is_empty());
        assert_eq!(words("''"), vec![""]);
    }
}
