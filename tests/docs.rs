//! The documentation against the code: the node reference is what `mesoflow docs` generates
//! today, the README stays a newcomer's page, every relative link of the README and the guide
//! leads to a file, and every `mesoflow` command the README and the guide show names a real
//! subcommand, validates, and runs (`GUIDE_COMMANDS` says how each is run).

use crate::common::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn md_files(dir: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            out.insert(name, std::fs::read_to_string(&p).unwrap());
        }
    }
    out
}

#[test]
fn the_committed_node_reference_is_current() {
    let s = Scratch::new();
    let out = s.path("reference");
    let r = mesoflow(&["docs", "--out", out.to_str().unwrap()], s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let fresh = md_files(&out);
    let committed = md_files(&root().join("docs/reference"));
    let stale: Vec<&String> = fresh
        .iter()
        .filter(|(k, v)| committed.get(*k) != Some(v))
        .map(|(k, _)| k)
        .chain(committed.keys().filter(|k| !fresh.contains_key(*k)))
        .collect();
    assert!(
        stale.is_empty(),
        "docs/reference is stale in {stale:?}: run `mesoflow docs --out docs/reference`"
    );
    // One page a kind, and the index names each.
    let kinds = mesoflow(&["nodes", "--json"], s.dir.path());
    let n = serde_json::from_str::<serde_json::Value>(&kinds.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .len();
    assert_eq!(fresh.len(), n + 1);
}

#[test]
fn the_readme_is_a_newcomer_s_page() {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(
        lines < 250,
        "README.md has {lines} lines; the rest belongs in docs/guide"
    );
    // Exactly the two set-up commands, in its first code block.
    let first_block: Vec<&str> = text
        .split("```sh\n")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap()
        .lines()
        .collect();
    assert_eq!(first_block.len(), 2, "{first_block:?}");
    assert!(first_block[0].starts_with("cargo run --release -- run graphs/quickstart.json"));
    assert!(first_block[1].starts_with("scripts/test"));
}

/// Words that speak of how mesoflow was made rather than of what it does: an issue's number, a
/// working session, a landing, the source texts' numbering, a machine lent.
fn speaks_of_its_making(line: &str) -> Option<&'static str> {
    let lower = line.to_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !c.is_alphanumeric() && c != '\'')
        .filter(|w| !w.is_empty())
        .collect();
    for (k, w) in words.iter().enumerate() {
        let next = words.get(k + 1).map_or("", |w| w.trim_end_matches("'s"));
        let before = if k > 0 { words[k - 1] } else { "" };
        match *w {
            "issue" | "issue's" | "issues" => return Some("an issue"),
            // A Python session is the user's, `session.rs` a module; any other is ours.
            "session" | "session's" | "sessions" if before != "python" && next != "rs" => {
                return Some("a session")
            }
            "landing" | "landings" => return Some("a landing"),
            "seed"
                if next.len() == 3
                    && next.starts_with('0')
                    && next.chars().all(|c| c.is_ascii_digit()) =>
            {
                return Some("a source text")
            }
            "lent" => return Some("a machine lent"),
            _ => {}
        }
    }
    None
}

#[test]
fn user_text_speaks_of_mesoflow_not_of_how_it_was_made() {
    let mut texts: Vec<(String, String)> = ["README.md", "BENCHMARKS.md", "docs/architecture.md"]
        .iter()
        .map(|f| {
            (
                f.to_string(),
                std::fs::read_to_string(root().join(f)).unwrap(),
            )
        })
        .collect();
    for folder in ["docs/guide", "docs/reference"] {
        for (name, text) in md_files(&root().join(folder)) {
            texts.push((format!("{folder}/{name}"), text));
        }
    }
    let graphs = root().join("graphs");
    for entry in std::fs::read_dir(&graphs).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json") {
            let g: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            if let Some(d) = g["description"].as_str() {
                texts.push((path.display().to_string(), d.to_string()));
            }
        }
    }
    let mut found = Vec::new();
    for (name, text) in &texts {
        for (n, line) in text.lines().enumerate() {
            if let Some(what) = speaks_of_its_making(line) {
                found.push(format!("{name}:{}: {what}: {line}", n + 1));
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
    // The check itself finds what it is for.
    assert_eq!(speaks_of_its_making("bounds (issue 57)"), Some("an issue"));
    assert_eq!(
        speaks_of_its_making("Seed 003's second half"),
        Some("a source text")
    );
    assert_eq!(
        speaks_of_its_making("for the Python session that made it"),
        None
    );
    assert_eq!(
        speaks_of_its_making("`session.rs` (the graph being edited)"),
        None
    );
    assert_eq!(speaks_of_its_making("seed 0's torus"), None);
}

/// The targets of `](…)` links that are neither web addresses nor anchors.
fn relative_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for part in text.split("](").skip(1) {
        let target = part.split(')').next().unwrap_or("");
        let target = target.split('#').next().unwrap_or("");
        if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
            out.push(target.to_string());
        }
    }
    out
}

#[test]
fn every_relative_link_of_the_readme_and_the_guide_leads_to_a_file() {
    let mut pages: Vec<PathBuf> = vec![
        root().join("README.md"),
        root().join("docs/architecture.md"),
    ];
    for name in md_files(&root().join("docs/guide")).keys() {
        pages.push(root().join("docs/guide").join(name));
    }
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for link in relative_links(&text) {
            let target = page.parent().unwrap().join(&link);
            if !target.exists() {
                broken.push(format!("{}: {link}", page.display()));
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    // Every page of the guide is in its table of contents.
    let summary = std::fs::read_to_string(root().join("docs/guide/SUMMARY.md")).unwrap();
    for name in md_files(&root().join("docs/guide")).keys() {
        assert!(
            name == "SUMMARY.md" || summary.contains(&format!("({name})")),
            "docs/guide/{name} is not in SUMMARY.md"
        );
    }
}

/// The `mesoflow …` command lines of a page's `sh` blocks, continuation lines joined, comments
/// and what the shell adds (`> file`, `| other`) cut off, spaces made single.
fn commands(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for block in text.split("```sh\n").skip(1) {
        let block = block.split("```").next().unwrap_or("");
        let joined = block.replace("\\\n", " ");
        for line in joined.lines() {
            let line = line.split(" #").next().unwrap_or("");
            let line = line.split(['>', '|']).next().unwrap_or("");
            let words: Vec<&str> = line.split_whitespace().collect();
            if words.first() == Some(&"mesoflow") {
                out.push(words[1..].join(" "));
            }
        }
    }
    out
}

#[test]
fn every_command_the_guide_shows_names_a_subcommand_and_graphs_that_validate() {
    let s = Scratch::new();
    let subcommands = mesoflow(&["--help"], s.dir.path()).stdout;
    let mut checked = 0;
    let mut problems = Vec::new();
    let mut pages = vec![root().join("README.md")];
    for name in md_files(&root().join("docs/guide")).keys() {
        pages.push(root().join("docs/guide").join(name));
    }
    for page in pages {
        let text = std::fs::read_to_string(&page).unwrap();
        for cmd in commands(&text).into_iter().chain(inline_commands(&text)) {
            let words: Vec<&str> = cmd.split_whitespace().collect();
            let sub = words[0];
            if !subcommands.contains(&format!("  {sub} ")) {
                problems.push(format!(
                    "{}: `mesoflow {cmd}`: no subcommand `{sub}`",
                    page.display()
                ));
                continue;
            }
            // A shipped graph it names must validate with the `--set`s the line gives.
            let Some(graph) = words
                .iter()
                .find(|w| w.starts_with("graphs/") && w.ends_with(".json"))
            else {
                continue;
            };
            let mut args = vec![
                "validate".to_string(),
                root().join(graph).display().to_string(),
            ];
            for (i, w) in words.iter().enumerate() {
                if *w == "--set" {
                    if let Some(v) = words.get(i + 1) {
                        args.push("--set".into());
                        args.push(v.to_string());
                    }
                }
            }
            // The nodes it names (`--render ID`, `--output ID.PORT`) are in that graph.
            let text = std::fs::read_to_string(root().join(graph)).unwrap();
            let nodes = serde_json::from_str::<serde_json::Value>(&text).unwrap()["nodes"].clone();
            for (i, w) in words.iter().enumerate() {
                if *w == "--render" || *w == "--output" {
                    let id = words
                        .get(i + 1)
                        .and_then(|v| v.split('.').next())
                        .unwrap_or("");
                    if nodes.get(id).is_none() {
                        problems.push(format!(
                            "{}: `mesoflow {cmd}`: {graph} has no node `{id}`",
                            page.display()
                        ));
                    }
                }
            }
            let argv: Vec<&str> = args.iter().map(String::as_str).collect();
            let r = mesoflow(&argv, s.dir.path());
            checked += 1;
            if r.code != 0 {
                problems.push(format!(
                    "{}: `mesoflow {cmd}`: {}",
                    page.display(),
                    r.stderr.trim()
                ));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(
        checked >= 10,
        "only {checked} commands with a shipped graph were checked"
    );
}

/// The `mesoflow …` commands quoted in a page's prose (single-backtick spans, which may wrap
/// across lines), outside the `sh` blocks; validated, not run: several take minutes (a 9-run
/// sweep of `graphs/btf_edit.json`, 256-sample truths).
fn inline_commands(text: &str) -> Vec<String> {
    let mut prose = String::new();
    for (i, part) in text.split("```").enumerate() {
        if i % 2 == 0 {
            prose.push_str(part);
        }
    }
    prose
        .split('`')
        .skip(1)
        .step_by(2)
        .filter_map(|span| {
            let words: Vec<&str> = span.split_whitespace().collect();
            (words.first() == Some(&"mesoflow") && words.len() > 1).then(|| words[1..].join(" "))
        })
        .collect()
}

/// How the guide's test runs a command the guide shows.
enum How {
    /// As written, in a scratch folder holding a copy of `graphs/` and `my.json` (the
    /// quickstart, as getting-started.md says), every page's commands in the page's order.
    AsWritten,
    /// As written, in the slow tier: it takes minutes here (the time measured, in the reason).
    Slow(&'static str),
    /// As written with these arguments added, for the reason given.
    With(&'static [&'static str], &'static str),
    /// `mesoflow serve` as written plus `--port 0`: it must start and serve the page.
    Serve,
    /// Not run here, for the reason given; the named test runs what it shows.
    By(&'static str, &'static str),
}

/// Every command the README and the guide show, as `commands` reads them, and how it is run.
/// A command missing here fails the test, and so does an entry the pages no longer show.
const GUIDE_COMMANDS: &[(&str, How)] = &[
    ("run graphs/btf_compress.json", How::AsWritten),
    (
        "run graphs/btf_compress.json --set capture.bounces=4",
        How::AsWritten,
    ),
    (
        "run graphs/truth.json --device cpu --set truth.bounces=4 --set truth.samples=64 \
         --set capture.bounces=4",
        How::Slow("a 4-bounce capture and a 4-bounce truth at 64 samples a pixel, about 40 s here"),
    ),
    (
        "run graphs/btf_environment.json --device cpu",
        How::Slow("a 4-bounce capture and a 4-bounce truth under the sky, about 50 s here"),
    ),
    (
        "explain graphs/btf_compress.json --set pca.rank=8",
        How::AsWritten,
    ),
    (
        "run graphs/btf_compress.json --set pca.rank=4",
        How::AsWritten,
    ),
    (
        "run graphs/btf_compress.json --output pca.rmse",
        How::AsWritten,
    ),
    (
        "sweep graphs/btf_compress.json --vary pca.rank=1,2,4,8 --measure pca.rmse",
        How::AsWritten,
    ),
    (
        "plan graphs/mdf_render.json --render torus_mdf --budget flip=0.2",
        How::AsWritten,
    ),
    (
        "plan graphs/family_translucent.json --render ours --against truth --budget rmse=0.1",
        How::Slow("two pilots, a truth probe and the candidates of the 64 × 48 scene, 6 s here"),
    ),
    (
        "plan graphs/mdf_render.json --render torus_mdf --against truth --budget rmse=0.2",
        How::Slow("the torus's true mesostructure displaced and path traced, then five candidates, 9 s here"),
    ),
    (
        "sweep graphs/btf_compress.json --set surface.size=128 --vary pca.rank=1,2,4,8,16 \
         --vary pca.solver=exact,randomized --vary pca.layout=texels,per_view --measure pca.rmse \
         --measure pca.compression_ratio --out-dir docs/sweeps/btf_pca",
        How::AsWritten,
    ),
    (
        "sweep graphs/btf_compress.json --vary pca.rank=1,2,4,8,16,32 --measure pca.rmse \
         --engine slurm --cache-dir /shared/mesoflow-cache --sbatch-args '--partition gpu \
         --gres gpu:1 --time 30' --max-queued 32 --retries 2",
        How::By(
            "slurm::a_sweep_on_two_workers_writes_what_a_local_sweep_writes",
            "needs a Slurm cluster with a shared /shared folder",
        ),
    ),
    (
        "status out/btf_compress/sweep/cluster",
        How::By(
            "slurm::status_follows_a_run_and_cancel_stops_it",
            "follows a cluster run, which needs Slurm",
        ),
    ),
    (
        "cancel out/btf_compress/sweep/cluster",
        How::By(
            "slurm::status_follows_a_run_and_cancel_stops_it",
            "stops a cluster run, which needs Slurm",
        ),
    ),
    (
        "cache gc --cache-dir /shared/mesoflow-cache --max-bytes 500G --older-than 30d",
        How::By(
            "cache::cache_gc_keeps_what_was_used_recently_and_fits_the_budget",
            "would act on this machine's /shared, never a test's to touch",
        ),
    ),
    ("nodes", How::AsWritten),
    ("validate my.json", How::AsWritten),
    (
        "run my.json --set surface.size=512 --output normals.rms_slope",
        How::AsWritten,
    ),
    (
        "watch my.json",
        How::With(&["--max-runs", "1"], "it re-runs until Ctrl-C"),
    ),
    ("serve my.json", How::Serve),
    (
        "sweep my.json --vary normals.scale=0.5,1,2,4 --vary surface.pattern=noise,cells \
         --measure normals.rms_slope",
        How::AsWritten,
    ),
    ("dot my.json --report out/my/report.json", How::AsWritten),
    ("schema", How::AsWritten),
    ("cache stats", How::AsWritten),
    ("cache gc --max-bytes 20G --older-than 30d", How::AsWritten),
    ("cache clear my.json", How::AsWritten),
    ("cache clear --all", How::AsWritten),
    (
        "sweep graphs/mdf_render.json --vary pca.rank=4,8,16,32 --vary lod.level=0,2 \
         --vary torus_mdf.use_mdf=false,true --set torus_mdf.frames=5 --measure error.rmse \
         --measure torus_mdf.frame_ms --measure torus_reference.frame_ms \
         --versus torus_mdf.frame_ms --out-dir out/mdf_sweep",
        How::Slow("16 renders of the torus with their references, 97 s here"),
    ),
    (
        "plan graphs/plan_verify.json --render btf_view --budget flip=0.05 -o out/plan/step.json",
        How::AsWritten,
    ),
    (
        "plan out/plan/step.json --render sss_view --budget flip=0.05 -o out/plan/planned.json",
        How::AsWritten,
    ),
    ("run out/plan/planned.json", How::AsWritten),
    ("serve graphs/mdf_render.json", How::Serve),
    ("run graphs/export.json", How::AsWritten),
    (
        "sweep graphs/sss_models.json --vary material.preset=apple,chicken1,chicken2,cream,\
         ketchup,marble,potato,skimmilk,skin1,skin2,spectralon,wholemilk --vary \
         profile.model=dipole,better_dipole,pbd --measure error.total_error_r --measure \
         error.total_error_b --measure error.l1 --out-dir out/sss_models_sweep",
        How::With(
            &["--set", "reference.photons=20000"],
            "the Monte Carlo reference at 2% of its photons: as written it traces 10^6 a \
             channel for each of the 12 materials, 570 s here; the same code, fewer photons",
        ),
    ),
    (
        "sweep graphs/sss_models.json --set material.preset=skin1 --vary \
         profile.points=16,32,64,128,256,1024,4096 --vary profile.model=dipole,better_dipole,pbd \
         --measure error.l1 --measure profile.seconds --versus profile.seconds --out-dir \
         out/sss_cost_sweep",
        How::AsWritten,
    ),
    (
        "sweep graphs/sss_render.json --vary marble.threshold=1,0.5,0.2,0.1,0.05,0.02,0.01 \
         --measure marble_error.rmse --measure marble.gather_seconds --versus \
         marble.gather_seconds --device cpu --out-dir out/sss_render_sweep",
        How::Slow("seven full-size renders of the torus with the body solver, 23 s here"),
    ),
];

/// Every page's commands in order, each with its entry in [`GUIDE_COMMANDS`]; fails on a
/// command without one and on an entry no page shows.
fn guide_commands() -> Vec<(String, &'static How)> {
    let mut pages = vec![root().join("README.md")];
    for name in md_files(&root().join("docs/guide")).keys() {
        pages.push(root().join("docs/guide").join(name));
    }
    let normal = |c: &str| c.split_whitespace().collect::<Vec<_>>().join(" ");
    let table: Vec<(String, &How)> = GUIDE_COMMANDS.iter().map(|(c, h)| (normal(c), h)).collect();
    let mut shown = Vec::new();
    let mut missing = Vec::new();
    for page in pages {
        for cmd in commands(&std::fs::read_to_string(&page).unwrap()) {
            match table.iter().find(|(c, _)| *c == cmd) {
                Some((_, how)) => shown.push((cmd, *how)),
                None => missing.push(format!("{}: `mesoflow {cmd}`", page.display())),
            }
        }
    }
    assert!(
        missing.is_empty(),
        "commands the guide shows that tests/docs.rs does not run (add each to GUIDE_COMMANDS):\n{}",
        missing.join("\n")
    );
    let gone: Vec<&String> = table
        .iter()
        .map(|(c, _)| c)
        .filter(|c| !shown.iter().any(|(s, _)| s == *c))
        .collect();
    assert!(
        gone.is_empty(),
        "GUIDE_COMMANDS entries no page shows: {gone:?}"
    );
    shown
}

/// Splits a command as the shell would (single quotes group words).
fn shell_words(cmd: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word = String::new();
    let mut quoted = false;
    let mut any = false;
    for ch in cmd.chars() {
        match ch {
            '\'' => {
                quoted = !quoted;
                any = true;
            }
            c if c.is_whitespace() && !quoted => {
                if any {
                    out.push(std::mem::take(&mut word));
                    any = false;
                }
            }
            c => {
                word.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(word);
    }
    out
}

/// Runs the guide's commands of one tier in a scratch folder as a user would after
/// `cp graphs/quickstart.json my.json`; every one must exit 0.
fn run_guide_commands(slow: bool) {
    let s = Scratch::new();
    // The graphs and their data, not a cache a user's earlier runs left beside them (gigabytes
    // after the guide's commands: copying it once filled this machine's disk).
    std::fs::create_dir_all(s.path("graphs")).unwrap();
    for entry in std::fs::read_dir(root().join("graphs")).unwrap() {
        let entry = entry.unwrap();
        if entry.file_name() == ".mesoflow" {
            continue;
        }
        let copy = std::process::Command::new("cp")
            .arg("-r")
            .arg(entry.path())
            .arg(s.path("graphs"))
            .status()
            .unwrap();
        assert!(copy.success(), "copying {}", entry.path().display());
    }
    std::fs::copy(root().join("graphs/quickstart.json"), s.path("my.json")).unwrap();
    let mut failed = Vec::new();
    let mut ran = 0;
    for (cmd, how) in guide_commands() {
        let mut words = shell_words(&cmd);
        match (how, slow) {
            (How::AsWritten | How::With(..) | How::Serve, false) | (How::Slow(_), true) => {}
            (How::By(test, why), false) => {
                eprintln!("`mesoflow {cmd}` is run by {test}: this one {why}");
                let (file, name) = test.split_once("::").unwrap();
                let text = std::fs::read_to_string(root().join(format!("tests/{file}.rs")))
                    .unwrap_or_default();
                assert!(
                    text.contains(&format!("fn {name}(")),
                    "`mesoflow {cmd}` is said to be run by {test}, which does not exist"
                );
                continue;
            }
            _ => continue,
        }
        match how {
            How::With(extra, why) => {
                eprintln!("`mesoflow {cmd}` with {extra:?} added: {why}");
                words.extend(extra.iter().map(|w| w.to_string()));
            }
            How::Slow(why) => eprintln!("`mesoflow {cmd}` (slow: {why})"),
            _ => {}
        }
        ran += 1;
        if let How::Serve = how {
            words.extend(["--port".into(), "0".into()]);
            if let Err(e) = serve_once(&words, s.dir.path()) {
                failed.push(format!("`mesoflow {cmd}`: {e}"));
            }
            continue;
        }
        let args: Vec<&str> = words.iter().map(String::as_str).collect();
        let t = std::time::Instant::now();
        let r = mesoflow(&args, s.dir.path());
        eprintln!("{:.1} s: `mesoflow {cmd}`", t.elapsed().as_secs_f64());
        if r.code != 0 {
            failed.push(format!(
                "`mesoflow {cmd}` exited {}: {}",
                r.code,
                r.stderr.trim()
            ));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
    assert!(ran > 0, "no command of this tier ran");
    if slow {
        mdf_sweep_holds_the_guides_figures(&s.path("out/mdf_sweep/sweep.csv"));
    }
}

/// docs/guide/mdf.md on the sweep its command makes: leaving the MDF out costs more error
/// (measured 0.080–0.083) than any rank or level with it (0.015–0.039). Held: every row without
/// the MDF above every row with it, and each range within 2× of the measured one.
fn mdf_sweep_holds_the_guides_figures(csv: &Path) {
    let text = std::fs::read_to_string(csv).unwrap_or_else(|e| panic!("{}: {e}", csv.display()));
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (mdf, rmse) = (col("torus_mdf.use_mdf"), col("error.rmse"));
    let (mut with, mut without) = (Vec::new(), Vec::new());
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let e: f64 = f[rmse].parse().unwrap();
        if f[mdf] == "true" {
            with.push(e)
        } else {
            without.push(e)
        }
    }
    let range = |v: &[f64]| {
        (
            v.iter().copied().fold(f64::INFINITY, f64::min),
            v.iter().copied().fold(0.0, f64::max),
        )
    };
    let ((w_lo, w_hi), (o_lo, o_hi)) = (range(&with), range(&without));
    eprintln!("mdf sweep: with the MDF {w_lo:.3}–{w_hi:.3}, without {o_lo:.3}–{o_hi:.3}");
    assert!(with.len() == 8 && without.len() == 8, "{text}");
    assert!(
        o_lo > w_hi,
        "without the MDF {o_lo} is not above with it {w_hi}"
    );
    assert!(
        w_lo > 0.015 / 2.0 && w_hi < 0.039 * 2.0,
        "with the MDF {w_lo}–{w_hi}"
    );
    assert!(
        o_lo > 0.080 / 2.0 && o_hi < 0.083 * 2.0,
        "without the MDF {o_lo}–{o_hi}"
    );
}

/// Starts `mesoflow serve …`, reads the URL it prints and fetches the page with its token.
fn serve_once(words: &[String], cwd: &Path) -> Result<(), String> {
    use std::io::{BufRead, BufReader, Read, Write};
    let mut child = bin()
        .args(words)
        .current_dir(cwd)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map_err(|e| e.to_string())?;
    let result = (|| {
        let mut lines = BufReader::new(child.stdout.take().ok_or("no stdout")?);
        let mut line = String::new();
        while !line.contains("http://") {
            line.clear();
            if lines.read_line(&mut line).map_err(|e| e.to_string())? == 0 {
                return Err("exited without printing its URL".to_string());
            }
        }
        let url = line[line.find("http://").unwrap()..].trim().to_string();
        let rest = url.trim_start_matches("http://");
        let (addr, query) = rest.split_once('/').ok_or("no path in the URL")?;
        let mut tcp = std::net::TcpStream::connect(addr).map_err(|e| e.to_string())?;
        tcp.set_read_timeout(Some(std::time::Duration::from_secs(60)))
            .ok();
        write!(
            tcp,
            "GET /{query} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
        )
        .map_err(|e| e.to_string())?;
        let mut reply = String::new();
        tcp.read_to_string(&mut reply).map_err(|e| e.to_string())?;
        if !reply.starts_with("HTTP/1.1 200") || !reply.contains("<html") {
            return Err(format!(
                "the page was not served: {}",
                reply.lines().next().unwrap_or("")
            ));
        }
        Ok(())
    })();
    let _ = child.kill();
    let _ = child.wait();
    result
}

#[test]
fn every_command_the_guide_shows_runs() {
    run_guide_commands(false);
}

#[test]
#[ignore = "slow: the guide's commands that take minutes (GUIDE_COMMANDS' How::Slow)"]
fn every_slow_command_the_guide_shows_runs() {
    run_guide_commands(true);
}

/// `docs/architecture.md`'s code map is a map of the tree as it is: every folder its first
/// column names exists, and every source folder (each crate's `src` and the folders in it,
/// and the project's other top-level folders of code) has a row.
#[test]
fn the_architecture_code_map_names_every_source_folder_and_only_real_ones() {
    let text = std::fs::read_to_string(root().join("docs/architecture.md")).unwrap();
    let map = text
        .split("## Code map")
        .nth(1)
        .and_then(|t| t.split("\n## ").next())
        .expect("a Code map section");
    let rows: Vec<String> = map
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .map(String::from)
        .collect();
    assert!(rows.len() > 20, "{rows:?}");
    let missing: Vec<&String> = rows.iter().filter(|r| !root().join(r).is_dir()).collect();
    assert!(
        missing.is_empty(),
        "the code map names folders that do not exist: {missing:?}"
    );
    // Every folder of source code: the crates' `src` and each folder in it (not deeper: a
    // node kind's own folder is its prefix's row), and the top-level folders of code.
    let mut want: Vec<String> = Vec::new();
    for src in ["graph/src", "runtime/src", "nodes/src", "src"] {
        want.push(src.to_string());
        for e in std::fs::read_dir(root().join(src)).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                want.push(format!("{src}/{}", e.file_name().to_string_lossy()));
            }
        }
    }
    want.extend(
        [
            "plan", "python", "testkit", "tests", "benches", "scripts", "docs",
        ]
        .map(String::from),
    );
    let absent: Vec<&String> = want.iter().filter(|w| !rows.contains(w)).collect();
    assert!(
        absent.is_empty(),
        "source folders without a row in the code map: {absent:?}"
    );
}
