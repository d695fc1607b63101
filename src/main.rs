//! `mesoflow`: run, check, inspect, watch and sweep appearance-modeling pipelines.
//!
//! Only this package touches the terminal: progress bars, tables, colours and exit codes
//! (0 ok, 1 run failed, 2 invalid graph or arguments, 130 cancelled).

mod args;
mod commands;
mod env;
mod exit;
mod interrupt;
mod load;
mod plan;
mod progress;

use clap::Parser;

fn main() {
    let filter = tracing_subscriber::EnvFilter::try_from_env("MESOFLOW_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("error,wgpu_hal=off,wgpu_core=off"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    env::quiet_broken_pipes();
    env::quiet_vulkan_device_select();
    let cli = args::Cli::parse();
    let code = match env::check().and_then(|()| commands::dispatch(cli)) {
        Ok(code) => code,
        Err(e) => {
            let code = exit::code_of(&e);
            eprintln!("error: {e:#}");
            code
        }
    };
    std::process::exit(code);
}
