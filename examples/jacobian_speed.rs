//! Autodiff against the hand-derived Analytic Jacobian, written the Burn-example way:
//! pick the backends, time both methods, print the table that `doma bench` prints.
//!
//! ```text
//! cargo run --release --example jacobian_speed -- [flex|ndarray|wgpu|all] [STEPS]
//! ```

use doma::backend::{BackendKind, wgpu_available};
use doma::experiments::speed::{self, BenchJob};

fn main() -> anyhow::Result<()> {
    doma::backend::tune_allocator();
    let mut args = std::env::args().skip(1);
    let backends = match args.next().as_deref() {
        None | Some("flex") => vec![BackendKind::Flex],
        Some("ndarray") => vec![BackendKind::Ndarray],
        Some("wgpu") => vec![BackendKind::Wgpu],
        Some("all") => {
            let mut b = vec![BackendKind::Flex, BackendKind::Ndarray];
            if wgpu_available() {
                b.push(BackendKind::Wgpu);
            }
            b
        }
        Some(other) => anyhow::bail!("unknown backend `{other}` (flex, ndarray, wgpu or all)"),
    };
    let steps = match args.next() {
        Some(s) => s
            .parse()
            .ok()
            .filter(|&n: &usize| n > 0)
            .ok_or_else(|| anyhow::anyhow!("STEPS must be a positive integer, not `{s}`"))?,
        None => 30,
    };
    let job = BenchJob {
        backends,
        steps,
        ..BenchJob::default()
    };
    let rows = speed::run(&job, |r| {
        eprintln!("{:?} {} {}: {:.2} ms", r.kind, r.backend, r.method, r.ms)
    })?;
    print!("{}", speed::table(&rows));
    Ok(())
}
