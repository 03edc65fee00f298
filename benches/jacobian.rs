//! Outputs + J + the backward of `L_H` through them (Affinity, d = 128, n = 2) at 1,024
//! and 16,384 points, for `Autodiff` and `Analytic`, on flex, ndarray and wgpu (when an
//! adapter exists).
//!
//! `cargo bench --bench jacobian`

use burn::tensor::{Tensor, TensorData};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use doma::backend::{BackendKind, wgpu_available};
use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::jacobian::JacobianKind;
use doma::loss::{self, SmoothnessNorm};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn jacobian(c: &mut Criterion) {
    doma::backend::tune_allocator();
    let mut group = c.benchmark_group("jacobian");
    group.sample_size(10);
    let mut backends = vec![BackendKind::Flex, BackendKind::Ndarray];
    if wgpu_available() {
        backends.push(BackendKind::Wgpu);
    }
    for backend in backends {
        let device = backend.device().expect("a backend that runs here");
        let ad = device.clone().autodiff();
        let field = DomaFieldConfig::new(Variant::Affinity).init(0, &ad);
        for points in [1024usize, 16384] {
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let x: Vec<f32> = (0..3 * points)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let x = Tensor::<2>::from_data(TensorData::new(x, [points, 3]), &ad);
            for method in [JacobianKind::Autodiff, JacobianKind::Analytic] {
                let jac = method.method();
                let id = BenchmarkId::new(format!("{backend}/{method}"), points);
                group.bench_function(id, |b| {
                    b.iter(|| {
                        let raw = field.raw_dual(x.clone(), 0.5, jac.as_ref());
                        let tangent = raw.tangent.expect("tangents");
                        let l =
                            loss::smoothness(tangent, SmoothnessNorm::Squared) + raw.value.mean();
                        let grads = l.backward();
                        doma::readback::sync(&device).expect("the device syncs");
                        grads
                    })
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, jacobian);
criterion_main!(benches);
