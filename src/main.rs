//! `mesoflow`: run, check, inspect, watch, sweep and plan appearance-modeling pipelines. The
//! command line itself lives in the library (`lib.rs`), which the Python package embeds too.

fn main() {
    let filter = tracing_subscriber::EnvFilter::try_from_env("MESOFLOW_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("error,wgpu_hal=off,wgpu_core=off"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    std::process::exit(mesoflow::main(std::env::args_os()));
}
