//! Runs Embark's `texture-synthesis` on one exemplar and prints the seconds it took, so the
//! mesoflow bench (`benches/synthesis.rs`) can measure the same energy on its output.
//!
//! Usage: texture-synthesis-peer EXEMPLAR.png OUT.png WIDTH HEIGHT SEED

use std::time::Instant;
use texture_synthesis as ts;

fn main() -> Result<(), ts::Error> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 6 {
        eprintln!("usage: texture-synthesis-peer EXEMPLAR.png OUT.png WIDTH HEIGHT SEED");
        std::process::exit(2);
    }
    let (w, h): (u32, u32) = (args[3].parse().unwrap_or(256), args[4].parse().unwrap_or(256));
    let seed: u64 = args[5].parse().unwrap_or(1);
    let start = Instant::now();
    let session = ts::Session::builder()
        .add_example(&args[1])
        .output_size(ts::Dims::new(w, h))
        .seed(seed)
        .build()?;
    let generated = session.run(None);
    let seconds = start.elapsed().as_secs_f64();
    generated.save(&args[2])?;
    println!("{seconds:.4}");
    Ok(())
}
