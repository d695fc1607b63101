//! The `mesoflow` command line as a library. The binary (`main.rs`) calls [`main`]; the Python
//! package calls [`run_embedded`], so `mesoflow.cli([...])` does in its process whatever the
//! command line does (plan, watch, dot, cache, …). Sweep tables and charts are public for the
//! Python package's `mesoflow.sweep`, which writes them through the same code.
//!
//! Only this package touches the terminal: progress bars, tables, colours and exit codes
//! (0 ok, 1 run failed, 2 invalid graph or arguments, 130 cancelled).

mod args;
pub mod chart;
mod cluster;
mod commands;
mod env;
mod exit;
mod interrupt;
mod load;
mod progress;
pub mod reference;
mod session;
mod studio;
pub mod sweep;

use clap::Parser;
use std::ffi::OsString;
use std::sync::atomic::Ordering;

fn dispatch(cli: args::Cli) -> i32 {
    match env::check().and_then(|()| commands::dispatch(cli)) {
        Ok(code) => code,
        Err(e) => {
            let code = exit::code_of(&e);
            eprintln!("error: {e:#}");
            code
        }
    }
}

/// The command line of the `mesoflow` binary: parses `args` (the program name first), exits
/// the process on a usage error as clap does, and returns the exit code.
pub fn main(args: impl IntoIterator<Item = OsString>) -> i32 {
    env::quiet_broken_pipes();
    env::quiet_vulkan_device_select();
    dispatch(args::Cli::parse_from(args))
}

/// The command line inside a host process: a usage error is printed and returned as exit code 2
/// (`--help` as 0) instead of ending the process, and Ctrl-C is the host's, which calls
/// [`cancel`]. One command at a time.
pub fn run_embedded(args: &[String]) -> i32 {
    interrupt::set_embedded();
    interrupt::cancel_flag().store(false, Ordering::SeqCst);
    match args::Cli::try_parse_from(args) {
        Ok(cli) => dispatch(cli),
        Err(e) => {
            let _ = e.print();
            if e.use_stderr() {
                exit::INVALID
            } else {
                exit::OK
            }
        }
    }
}

/// Cancels the command [`run_embedded`] is running, as a first Ctrl-C would.
pub fn cancel() {
    interrupt::cancel_flag().store(true, Ordering::SeqCst);
}
