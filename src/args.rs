//! Command-line arguments (clap).

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "mesoflow",
    version,
    about = "Data-flow graphs for data-driven appearance modeling"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run a graph: compute the requested outputs, reusing cached results.
    Run(RunArgs),
    /// What `run` with the same arguments would re-run and why, without running anything:
    /// every node the outputs need, read from a cache, not needed, or run (the first run,
    /// --no-cache, an evicted value, or what changed since the last run into the output folder).
    Explain(RunArgs),
    /// Check a graph without running it.
    Validate {
        graph: PathBuf,
        #[arg(long = "set", value_name = "ID.PARAM=VALUE")]
        set: Vec<String>,
    },
    /// List node kinds, or describe one.
    Nodes {
        /// A kind to describe (`render.mesh`), or a prefix whose kinds to list (`btf`).
        kind: Option<String>,
        /// Machine-readable: a JSON array, one object per kind.
        #[arg(long)]
        json: bool,
    },
    /// Print the JSON Schema of graph files (for editors).
    Schema,
    /// Write the node reference: one Markdown page per kind (ports, parameters, defaults,
    /// documentation) and an index, generated from the catalog.
    Docs {
        /// The folder to write into (docs/reference in this repository).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Print a graph in Graphviz dot.
    Dot {
        graph: PathBuf,
        /// Colour nodes by their status in this run report.
        #[arg(long, value_name = "REPORT_JSON")]
        report: Option<PathBuf>,
    },
    /// Re-run a graph whenever it or a file it reads changes.
    Watch {
        #[command(flatten)]
        run: RunArgs,
        /// Poll interval in milliseconds.
        #[arg(long, default_value_t = 500)]
        interval_ms: u64,
        /// Stop after this many runs (for scripts and tests).
        #[arg(long)]
        max_runs: Option<usize>,
    },
    /// Run a graph over a grid of parameter values; write sweep.csv and charts.
    Sweep(SweepArgs),
    /// Open a graph in the studio, in the browser: see it, tune parameters, watch only what
    /// changed re-run, look at every result.
    Serve(ServeArgs),
    /// Choose each stage's cheapest model for a render's view and a FLIP budget; write the
    /// planned graph and its plan (<graph>.plan.json).
    Plan(PlanArgs),
    /// The body of a cluster job: run one unit of a cluster run from the shared cache.
    Exec {
        /// The run folder the driver made (`<out-dir>/cluster` by default).
        run: PathBuf,
        #[arg(long)]
        unit: String,
    },
    /// The state of a cluster run: every unit, where it ran, its attempts.
    Status { run: PathBuf },
    /// Cancel a cluster run: its jobs are cancelled and its driver stops.
    Cancel { run: PathBuf },
    /// Inspect or clear the disk cache.
    Cache {
        #[command(subcommand)]
        action: CacheAction,
    },
}

#[derive(Subcommand)]
pub enum CacheAction {
    /// Entries and bytes, by node kind.
    Stats(CacheArgs),
    /// Remove every entry of a graph's cache (or --cache-dir's); --all: of every cache here and
    /// one folder down.
    Clear(ClearArgs),
    /// Remove entries unused for longer than --older-than, then the least recently used until
    /// at most --max-bytes remain (a hit renews an entry), and orphaned temporary files.
    Gc(GcArgs),
}

#[derive(Args)]
pub struct ClearArgs {
    #[command(flatten)]
    pub cache: CacheArgs,
    /// Without a graph or --cache-dir: clear every cache in this folder and one folder down
    /// (without it, they are listed and nothing is removed).
    #[arg(long)]
    pub all: bool,
}

#[derive(Args)]
pub struct GcArgs {
    #[command(flatten)]
    pub cache: CacheArgs,
    /// Keep at most this many bytes: a number or a size such as 512M, 20G.
    #[arg(long)]
    pub max_bytes: Option<String>,
    /// Remove entries not used for this long: 30d, 12h, 45m or 90s.
    #[arg(long)]
    pub older_than: Option<String>,
}

#[derive(Args)]
pub struct CacheArgs {
    /// Use the cache beside this graph, as `run` does (default: every .mesoflow/cache here and
    /// one folder down).
    pub graph: Option<PathBuf>,
    #[arg(long, env = "MESOFLOW_CACHE")]
    pub cache_dir: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SplitArg {
    Joint,
    Equal,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum DeviceArg {
    /// GPU nodes on a hardware GPU where there is one, else on their CPU path (with a warning).
    Auto,
    /// Every node on the CPU.
    Cpu,
    /// GPU nodes on a GPU adapter, software ones included; an error where there is none.
    Gpu,
}

/// The graph a command works on and the `--set`s applied to it (run, watch, sweep, plan).
#[derive(Args, Clone)]
pub struct GraphArgs {
    /// The graph file (JSON).
    #[arg(value_name = "GRAPH")]
    pub path: PathBuf,
    /// Override a parameter (value read as JSON, else as a string).
    #[arg(long = "set", value_name = "ID.PARAM=VALUE")]
    pub set: Vec<String>,
}

#[derive(Args, Clone)]
pub struct RunArgs {
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Produce only these outputs (default: every sink); each is printed after the run's table
    /// (a scalar by value), and alone with -q.
    #[arg(long = "output", value_name = "ID.PORT")]
    pub output: Vec<String>,
    /// Output folder (default: out/<graph name>/).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Where GPU nodes run.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    pub device: DeviceArg,
    /// No progress bars or summary table.
    #[arg(long, short)]
    pub quiet: bool,
    /// Say in the run table why each computed node ran: the first run, --no-cache, an evicted
    /// value, or what changed (a parameter, an input and the node that changed it, a file, the
    /// kind's version) since the last run into the same output folder.
    #[arg(long)]
    pub explain: bool,
    #[command(flatten)]
    pub cache: CacheOptions,
    #[command(flatten)]
    pub cluster: ClusterOptions,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum EngineArg {
    /// Here, on this machine's cores and GPU.
    Local,
    /// As Slurm jobs (`sbatch`), sharing `--cache-dir`, which must be on a shared filesystem.
    Slurm,
}

#[derive(Args, Clone)]
pub struct ClusterOptions {
    /// Where the work runs.
    #[arg(long, value_enum, default_value_t = EngineArg::Local)]
    pub engine: EngineArg,
    /// Passed to every sbatch, e.g. '--partition gpu --gres gpu:1 --time 30'.
    #[arg(long, value_name = "'ARGS'", allow_hyphen_values = true)]
    pub sbatch_args: Option<String>,
    /// At most this many jobs queued or running at once.
    #[arg(long, default_value_t = 64)]
    pub max_queued: usize,
    /// Resubmissions of a unit whose job was lost or killed, or found an input missing.
    #[arg(long, default_value_t = 2)]
    pub retries: u32,
    /// Submit the driver itself as a Slurm job and return; `mesoflow status RUN` follows it.
    #[arg(long)]
    pub detach: bool,
    /// Make these nodes units of their own (by default a unit is a chain of nodes each with
    /// one consumer).
    #[arg(long, value_delimiter = ',', value_name = "ID,…")]
    pub split: Vec<String>,
    /// The run folder (default: <out-dir>/cluster).
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
}

#[derive(Args, Clone)]
pub struct CacheOptions {
    /// Disk cache folder (default: .mesoflow/cache beside the graph).
    #[arg(long, env = "MESOFLOW_CACHE")]
    pub cache_dir: Option<PathBuf>,
    /// Neither read nor write any cache.
    #[arg(long)]
    pub no_cache: bool,
    /// Recompute cache hits and fail if they differ.
    #[arg(long)]
    pub verify_cache: bool,
    /// Memory cache budget: bytes, or with K, M, G (default: a quarter of RAM).
    #[arg(long, value_name = "SIZE")]
    pub mem_budget: Option<String>,
}

#[derive(Args)]
pub struct SweepArgs {
    #[command(flatten)]
    pub graph: GraphArgs,
    /// A parameter and its values: id.param=v1,v2,… (repeat for a grid).
    #[arg(long = "vary", value_name = "ID.PARAM=V1,V2,…", required = true)]
    pub vary: Vec<String>,
    /// A scalar output to record: id.metric (repeat for several).
    #[arg(long = "measure", value_name = "ID.METRIC", required = true)]
    pub measure: Vec<String>,
    /// Also chart every other measure against this one (repeatable), e.g. a frame time: one
    /// line per combination of the other varied values, along the first --vary.
    #[arg(long = "versus", value_name = "ID.METRIC")]
    pub versus: Vec<String>,
    /// The most runs the varies may make; a larger grid is refused before anything runs.
    #[arg(long, value_name = "N", default_value_t = crate::sweep::MAX_RUNS)]
    pub max_runs: usize,
    /// Output folder (default: out/<graph name>/sweep/, where the studio writes its sweeps).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Where GPU nodes run.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    pub device: DeviceArg,
    /// No progress bars; only the result.
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub cache: CacheOptions,
    #[command(flatten)]
    pub cluster: ClusterOptions,
}

/// What `mesoflow plan --against` judges by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AgainstArg {
    /// A truth the graph makes (brute force of the same scene).
    Truth,
}

#[derive(Args)]
pub struct PlanArgs {
    #[command(flatten)]
    pub graph: GraphArgs,
    /// The render node to plan (render.mesh, sss.render or qh.render).
    #[arg(long, value_name = "ID")]
    pub render: String,
    /// The error the view may show: flip=B, the mean FLIP over the object's pixels against the
    /// graph's own model (0 = the full model; 1 or more = the cheapest); with `--against truth`,
    /// rmse=B (the relative RMSE against the truth) or flip=B (the mean FLIP against it).
    #[arg(long, value_name = "flip=B|rmse=B")]
    pub budget: String,
    /// Judge every candidate, across model families and brute force, against a truth the graph
    /// makes (sss.render: its mesh filled with its medium, path traced; render.mesh: its
    /// captured height field displaced, path traced) instead of against the graph's own model;
    /// the cheapest within the budget is planned. Where the graph makes no truth, a FLIP budget
    /// falls back to the graph's own model.
    #[arg(long, value_enum, value_name = "truth")]
    pub against: Option<AgainstArg>,
    /// The planned graph (default: <graph>.planned.json beside the graph; its plan, <graph>.plan.json, goes beside it).
    #[arg(short = 'o', long = "output", value_name = "OUT.json")]
    pub output: Option<PathBuf>,
    /// The viewer's pixels per degree the budget is judged at (default FLIP's 67: a 0.7 m wide
    /// 4K display at 0.7 m).
    #[arg(long, value_name = "P", conflicts_with = "viewer")]
    pub ppd: Option<f64>,
    /// The viewer as distance and image width in metres (DIST_M,WIDTH_M), the ppd following
    /// from the render's width in pixels as `image.flip`'s `viewer` does.
    #[arg(long, value_name = "DIST_M,WIDTH_M")]
    pub viewer: Option<String>,
    /// How a render.mesh's budget is shared by its BTF and MDF: `joint` (the share that
    /// predicts the least render time) or `equal` (half each).
    #[arg(long, value_enum, default_value_t = SplitArg::Joint)]
    pub split: SplitArg,
    /// The time the plan may spend proving itself on probes of the view, in renders of the
    /// full view (the graph's own frame): each candidate is rendered on the probe beside the
    /// graph and kept only within the budget and not slower. 0: no probe, the measured model
    /// alone.
    #[arg(long, value_name = "RENDERS", default_value_t = 1.0)]
    pub probe_budget: f64,
    /// The probe frame's share of the render's pixels (its centre, at the same pixels per
    /// degree); default 0.25, and 0.1 with `--against truth` (its truth probe, at a third of
    /// the budget's noise, costs about 7.3 × this share frames of brute force at the budget).
    #[arg(long, value_name = "FRACTION")]
    pub probe_share: Option<f64>,
    /// Where GPU nodes run.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    pub device: DeviceArg,
    /// No progress bars; only the result.
    #[arg(long, short)]
    pub quiet: bool,
    /// Every candidate and probe with its measures and warnings (by default a summary: what
    /// was tried, what was planned and why; the plan file holds the detail either way).
    #[arg(long, short)]
    pub verbose: bool,
    #[command(flatten)]
    pub cache: CacheOptions,
}

#[derive(Args)]
pub struct ServeArgs {
    pub graph: PathBuf,
    /// Port to listen on (0: any free port).
    #[arg(long, default_value_t = 7878)]
    pub port: u16,
    /// Address to listen on. The default answers this machine only; the token is required
    /// whatever the address.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Open the studio in the default browser.
    #[arg(long)]
    pub open: bool,
    /// Output folder (default out/<graph name>).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Where GPU nodes run.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    pub device: DeviceArg,
    #[command(flatten)]
    pub cache: CacheOptions,
    /// How often the graph file is checked for changes made in an editor, in milliseconds.
    #[arg(long, default_value_t = 500)]
    pub interval_ms: u64,
}
