//! One module per subcommand; `dispatch` routes to them and returns the exit code.

mod cache;
mod info;
mod plan;
pub(crate) mod run;
mod sweep;
mod watch;

use crate::args::{CacheAction, Cli, Command};

pub fn dispatch(cli: Cli) -> anyhow::Result<i32> {
    match cli.command {
        Command::Run(args) => run::run(&args),
        Command::Explain(args) => run::explain(&args),
        Command::Validate { graph, set } => info::validate(&graph, &set),
        Command::Nodes { kind, json } => info::nodes(kind.as_deref(), json),
        Command::Schema => info::schema(),
        Command::Docs { out } => crate::reference::write(&out),
        Command::Dot { graph, report } => info::dot(&graph, report.as_deref()),
        Command::Watch {
            run,
            interval_ms,
            max_runs,
        } => watch::watch(&run, interval_ms, max_runs),
        Command::Sweep(args) => sweep::sweep(&args),
        Command::Serve(args) => crate::studio::serve(&args),
        Command::Exec { run, unit } => crate::cluster::exec::exec(&run, &unit),
        Command::Status { run } => crate::cluster::status(&run),
        Command::Cancel { run } => crate::cluster::cancel(&run),
        Command::Plan(args) => plan::plan(&args),
        Command::Cache {
            action: CacheAction::Stats(a),
        } => cache::stats(&a),
        Command::Cache {
            action: CacheAction::Clear(a),
        } => cache::clear(&a),
        Command::Cache {
            action: CacheAction::Gc(a),
        } => cache::gc(&a),
    }
}
