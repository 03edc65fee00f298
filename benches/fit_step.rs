//! One training step of the synthetic protocol (750 trajectory points, T = 20),
//! DOMA-Affinity with and without the smoothness loss, on the CPU backends.
//!
//! `cargo bench --bench fit_step`

use criterion::{Criterion, criterion_group, criterion_main};
use doma::backend::BackendKind;
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::field::{DomaFieldConfig, Variant};
use doma::train::{FitConfig, Trainer};

fn fit_step(c: &mut Criterion) {
    let seq = benchmark_sequence(Motion::Rotation, 0).expect("the synthetic data");
    let mut group = c.benchmark_group("fit_step");
    group.sample_size(30);
    for backend in [BackendKind::Flex, BackendKind::Ndarray] {
        let device = backend.device().expect("a CPU backend");
        for (name, w_h) in [("affinity", 0.0), ("affinity-h", 0.1)] {
            let config = FitConfig::new(DomaFieldConfig::new(Variant::Affinity))
                .with_smoothness_weight(w_h)
                .with_quiet(true);
            let field = config.field.init(0, &device.clone().autodiff());
            let mut trainer = Trainer::new(field, &config, &seq.train, &device).expect("a trainer");
            let mut k = 0;
            group.bench_function(format!("{backend}/{name}"), |b| {
                b.iter(|| {
                    let losses = trainer.step(k % 20, 1e-4);
                    k += 1;
                    device.sync().expect("the device syncs");
                    losses
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, fit_step);
criterion_main!(benches);
