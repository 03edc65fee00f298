//! The synthetic benchmark (paper Tab. 2) written the Burn-example way: pick a device,
//! build a `FitConfig`, call `fit`, measure the EPE.
//!
//! ```text
//! cargo run --release --example synthetic -- [flex|ndarray|wgpu] [ITERATIONS]
//! ```
//! It fits DOMA-Affinity with and without the smoothness loss on the four motions.

use doma::backend::BackendKind;
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::field::{DomaFieldConfig, Variant};
use doma::metrics::{EPE_SCALE, evaluate_epe};
use doma::train::{FitConfig, fit};

fn main() -> anyhow::Result<()> {
    doma::backend::tune_allocator();
    let mut args = std::env::args().skip(1);
    let backend = match args.next().as_deref() {
        None | Some("flex") => BackendKind::Flex,
        Some("ndarray") => BackendKind::Ndarray,
        Some("wgpu") => BackendKind::Wgpu,
        Some(other) => anyhow::bail!("unknown backend `{other}` (flex, ndarray or wgpu)"),
    };
    let iterations: usize =
        match args.next() {
            Some(s) => s.parse().ok().filter(|&n| n > 0).ok_or_else(|| {
                anyhow::anyhow!("ITERATIONS must be a positive integer, not `{s}`")
            })?,
            None => 1000,
        };
    let device = backend.device()?;

    println!(
        "{:<14} {:>10} {:>10} {:>10} {:>12}",
        "EPE (x1e-4)", "rotation", "scaling", "shearing", "translation"
    );
    for (name, h_weight) in [("Affinity", 0.0), ("Affinity-H", 0.1)] {
        let mut row = format!("{name:<14}");
        for motion in Motion::ALL {
            let seq = benchmark_sequence(motion, 0)?;
            let config = FitConfig::new(DomaFieldConfig::new(Variant::Affinity))
                .with_iterations(iterations)
                .with_smoothness_weight(h_weight)
                .with_quiet(true);
            let fitted = fit(&config, &seq.train, &device)?;
            let epe = evaluate_epe(&fitted.field, &seq.test, &device)? * EPE_SCALE;
            row += &format!(" {epe:>10.2}");
        }
        println!("{row}");
    }
    Ok(())
}
