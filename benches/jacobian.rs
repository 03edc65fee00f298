//! Outputs + J + the backward of `L_H` through them (Affinity, d = 128, n = 2) at 1,024
//! and 16,384 points, for `Autodiff` and `Analytic`, on flex, ndarray and wgpu (when an
//! adapter exists): the step of `doma bench`'s `jacobian` rows
//! ([`doma::experiments::speed::JacobianStep`]).
//!
//! `cargo bench --bench jacobian`

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use doma::backend::{BackendKind, wgpu_available};
use doma::experiments::speed::JacobianStep;
use doma::jacobian::JacobianKind;

fn jacobian(c: &mut Criterion) {
    doma::backend::tune_allocator();
    let mut group = c.benchmark_group("jacobian");
    group.sample_size(10);
    let mut backends = vec![BackendKind::Flex, BackendKind::Ndarray];
    if wgpu_available() {
        backends.push(BackendKind::Wgpu);
    }
    for backend in backends {
        for points in [1024usize, 16384] {
            for method in [JacobianKind::Autodiff, JacobianKind::Analytic] {
                let step =
                    JacobianStep::new(backend, method, points).expect("a backend that runs here");
                let id = BenchmarkId::new(format!("{backend}/{method}"), points);
                group.bench_function(id, |b| b.iter(|| step.run().expect("a step")));
            }
        }
    }
    group.finish();
}

criterion_group!(benches, jacobian);
criterion_main!(benches);
