//! Small utility kinds: scalar arithmetic (the trivial nodes of the scheduler benchmarks) and a
//! cancellable delay (for testing scheduling and cancellation).

pub mod scalar;
pub mod sleep;
