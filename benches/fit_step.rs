//! One training step of the synthetic protocol (750 trajectory points; `L_H` on min(1,024, 750)
//! = 750 jittered points; T = 20), DOMA-Affinity with and without the smoothness loss, for each CPU
//! backend and Jacobian method (and wgpu when an adapter exists): the step of `doma bench`'s
//! `fit_step` rows ([`doma::experiments::speed::FitStep`]). And one step of the DPF baseline
//! (T = 20 frame nets of the same width), whose SIRENs run through the method: Burn's `sin`
//! under `autodiff`, the fused sine layers under `analytic`.
//!
//! `cargo bench --bench fit_step`

use criterion::{Criterion, criterion_group, criterion_main};
use doma::backend::{BackendKind, wgpu_available};
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::experiments::speed::FitStep;
use doma::field::dpf::DpfConfig;
use doma::field::model::ModelConfig;
use doma::jacobian::JacobianKind;
use doma::train::FitConfig;

fn fit_step(c: &mut Criterion) {
    doma::backend::tune_allocator();
    let seq = benchmark_sequence(Motion::Rotation, 0).expect("the synthetic data");
    let mut group = c.benchmark_group("fit_step");
    group.sample_size(30);
    let mut backends = vec![BackendKind::Flex, BackendKind::Ndarray];
    if wgpu_available() {
        backends.push(BackendKind::Wgpu);
    }
    for backend in backends {
        let device = backend.device().expect("a backend that runs here");
        for (name, smoothness) in [("affinity", false), ("affinity-h", true)] {
            for method in [JacobianKind::Autodiff, JacobianKind::Analytic] {
                let mut step =
                    FitStep::synthetic(&seq.train, method, smoothness, &device).expect("a trainer");
                let id = format!("{backend}/{name}/{method}");
                group.bench_function(id, |b| b.iter(|| step.run().expect("a step")));
            }
        }
        for method in [JacobianKind::Autodiff, JacobianKind::Analytic] {
            let dpf = DpfConfig::new(seq.train.frames());
            let config = FitConfig::new(ModelConfig::Dpf(dpf)).with_jacobian(method);
            let mut step = FitStep::new(&config, &seq.train, &device).expect("a trainer");
            group.bench_function(format!("{backend}/dpf/{method}"), |b| {
                b.iter(|| step.run().expect("a step"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, fit_step);
criterion_main!(benches);
