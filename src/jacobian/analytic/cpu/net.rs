//! The whole SIREN as one operation on raw CPU buffers: the input layer, the hidden sine
//! layers and the output layer, values and (for the dual path) the three spatial
//! tangents, with one hand-written backward for every weight and bias (docs/design.md
//! §2.2, paper Eq. 6).
//!
//! Written once on slices; flex and ndarray hand their contiguous buffers to it
//! (`host.rs`). Per layer, the forward is one GEMM and one fused parallel pass, the
//! backward two GEMMs and one fused pass that also sums the bias gradient. The layout is
//! the stacked one, `S = [h; ḣ_x; ḣ_y; ḣ_z]` (`[4N, d]`), so that one GEMM serves the
//! values and the tangents. Three things a per-layer composition would pay for are gone:
//! - the input seeds `e_x, e_y, e_z` are never built: the first layer's tangent
//!   pre-activations are the first three rows of its weight matrix, read in place, and
//!   their gradient is a column sum;
//! - no buffer is zero-filled and then overwritten, and no `cat`/`slice` copies are made:
//!   the saved activations and the backward's temporaries come from a pool of
//!   workspaces that is filled on the first step and reused afterwards;
//! - no autodiff node per layer: the whole network is one node.

use super::gemm::{Mat, gemm};
use super::real::Real;
use super::rows::{Tangents, activate, activate_backward, column_sums};
use crate::jacobian::analytic::OpSpec;

/// One layer's parameters, row-major: `w` is `[d_in, d_out]` (Burn's `Linear` layout).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layer<'a, E> {
    pub w: &'a [E],
    pub b: &'a [E],
    pub d_in: usize,
    pub d_out: usize,
}

/// What the backward needs from the forward: for each sine layer `l`, its pre-activation
/// `Z_l = S_{l-1} W_l` (the first layer's without tangent rows, which are `W_0`'s first
/// rows) and its output `S_l`.
#[derive(Debug)]
pub(crate) struct Activations<E: Real> {
    z: Vec<Vec<E>>,
    s: Vec<Vec<E>>,
}

impl<E: Real> Drop for Activations<E> {
    fn drop(&mut self) {
        for v in self.z.drain(..).chain(self.s.drain(..)) {
            E::pool().give(v);
        }
    }
}

/// A SIREN over borrowed parameters: its layers (the sine layers, then the output
/// layer), `ω`, and whether the tangents ride along.
pub(crate) struct Net<'a, E> {
    layers: Vec<Layer<'a, E>>,
    omega: f64,
    dual: bool,
}

impl<'a, E: Real> Net<'a, E> {
    /// The network over a flat parameter buffer `[W_0, b_0, …, W_o, b_o]` laid out by
    /// `spec`'s shapes.
    pub(crate) fn new(flat: &'a [E], spec: &OpSpec) -> Self {
        Net {
            layers: layers_of(flat, &spec.shapes),
            omega: spec.omega,
            dual: spec.dual,
        }
    }

    /// The number of points in an input `x` (`[n, c]`).
    fn points(&self, x: &[E]) -> usize {
        x.len() / self.layers[0].d_in.max(1)
    }

    /// The SIREN at `x` (`[n, c]`, row-major; tangents seeded on its first three columns
    /// when dual): the output `[n, O]`, or `[4n, O]` stacked values and tangents, and the
    /// activations the backward needs.
    pub(crate) fn forward(&self, x: &[E]) -> (Vec<E>, Activations<E>) {
        let (n, omega, dual) = (self.points(x), self.omega, self.dual);
        let (out_layer, sine) = self
            .layers
            .split_last()
            .expect("a SIREN has an output layer");
        assert!(!sine.is_empty(), "a SIREN has a sine layer");
        let blocks = if dual { 4 } else { 1 };
        let w = E::from_f64(omega);
        let mut acts = Activations {
            z: Vec::with_capacity(sine.len()),
            s: Vec::with_capacity(sine.len()),
        };
        for (l, layer) in sine.iter().enumerate() {
            let d = layer.d_out;
            let (input, rows) = match l {
                0 => (x, n),
                _ => (&acts.s[l - 1][..], blocks * n),
            };
            let mut z = E::pool().take(rows * d);
            gemm(
                &mut z,
                Mat::new(input, rows, layer.d_in),
                Mat::new(layer.w, layer.d_in, d),
                false,
            );
            let tangents = dual.then_some(match l {
                0 => Tangents::Seed(layer.w),
                _ => Tangents::Stacked(&z),
            });
            let s = activate(&z, tangents, layer.b, w, n, d);
            acts.z.push(z);
            acts.s.push(s);
        }
        let (d, o) = (out_layer.d_in, out_layer.d_out);
        let mut out = vec![E::zero(); blocks * n * o];
        let last = acts.s.last().expect("a sine layer's output");
        gemm(
            &mut out,
            Mat::new(last, blocks * n, d),
            Mat::new(out_layer.w, d, o),
            false,
        );
        // The bias moves the values only.
        for row in out[..n * o].chunks_exact_mut(o) {
            row.iter_mut()
                .zip(out_layer.b)
                .for_each(|(v, b)| *v = *v + *b);
        }
        (out, acts)
    }

    /// The gradients of a loss whose gradient with respect to [`Net::forward`]'s output
    /// is `g_out`: every layer's `(g_W, g_b)` written into `g_params` (laid out like the
    /// parameters, see [`split_layers`]), and `g_x` when `input_grad`.
    pub(crate) fn backward(
        &self,
        acts: &Activations<E>,
        x: &[E],
        g_out: &[E],
        input_grad: bool,
        g_params: &mut [E],
    ) -> Option<Vec<E>> {
        let (n, omega, dual, layers) = (self.points(x), self.omega, self.dual, &self.layers[..]);
        let (out_layer, sine) = layers.split_last().expect("a SIREN has an output layer");
        assert!(!sine.is_empty(), "a SIREN has a sine layer");
        let blocks = if dual { 4 } else { 1 };
        let w = E::from_f64(omega);
        let shapes: Vec<[usize; 2]> = layers.iter().map(|l| [l.d_in, l.d_out]).collect();
        let mut slots = split_layers(g_params, &shapes);

        // Output layer: g_b = Σ value rows, g_W = S_Lᵀ G, g_S = G W_oᵀ.
        let (d, o) = (out_layer.d_in, out_layer.d_out);
        let (g_w, g_b) = slots.pop().expect("the output layer's slot");
        g_b.fill(E::zero());
        column_sums(&g_out[..n * o], o, g_b);
        let last = acts.s.last().expect("a sine layer's output");
        gemm(
            g_w,
            Mat::new(last, blocks * n, d).t(),
            Mat::new(g_out, blocks * n, o),
            false,
        );
        let mut g_s = E::pool().take(blocks * n * d);
        gemm(
            &mut g_s,
            Mat::new(g_out, blocks * n, o),
            Mat::new(out_layer.w, d, o).t(),
            false,
        );

        let mut g_x = None;
        for (l, layer) in sine.iter().enumerate().rev() {
            let (d_in, d) = (layer.d_in, layer.d_out);
            let (g_w, g_b) = slots.pop().expect("a sine layer's slot");
            let tangents = dual.then_some(match l {
                0 => Tangents::Seed(layer.w),
                _ => Tangents::Stacked(&acts.z[l]),
            });
            let (g_z, sums) = activate_backward(&acts.z[l], tangents, layer.b, &g_s, w, n, d);
            E::pool().give(std::mem::take(&mut g_s));
            g_b.copy_from_slice(&sums[..d]);
            if l > 0 {
                gemm(
                    g_w,
                    Mat::new(&acts.s[l - 1], blocks * n, d_in).t(),
                    Mat::new(&g_z, blocks * n, d),
                    false,
                );
                g_s = E::pool().take(blocks * n * d_in);
                gemm(
                    &mut g_s,
                    Mat::new(&g_z, blocks * n, d),
                    Mat::new(layer.w, d_in, d).t(),
                    false,
                );
            } else {
                // The input's tangent rows are the seeds e_k: their part of g_W is the column
                // sum of each tangent block, added to row k.
                gemm(
                    g_w,
                    Mat::new(x, n, d_in).t(),
                    Mat::new(&g_z[..n * d], n, d),
                    false,
                );
                if dual {
                    for k in 0..3 {
                        let row = &mut g_w[k * d..(k + 1) * d];
                        let s = &sums[(k + 1) * d..(k + 2) * d];
                        row.iter_mut().zip(s).for_each(|(a, b)| *a = *a + *b);
                    }
                }
                if input_grad {
                    let mut gx = vec![E::zero(); n * d_in];
                    gemm(
                        &mut gx,
                        Mat::new(&g_z[..n * d], n, d),
                        Mat::new(layer.w, d_in, d).t(),
                        false,
                    );
                    g_x = Some(gx);
                }
            }
            E::pool().give(g_z);
        }
        g_x
    }
}

/// Splits a buffer laid out like the parameters, `[W_0, b_0, …, W_o, b_o]` flattened, into
/// each layer's `(W, b)`.
pub(crate) fn split_layers<'a, E>(
    mut flat: &'a mut [E],
    shapes: &[[usize; 2]],
) -> Vec<(&'a mut [E], &'a mut [E])> {
    shapes
        .iter()
        .map(|&[d_in, d_out]| {
            let (w, rest) = std::mem::take(&mut flat).split_at_mut(d_in * d_out);
            let (b, rest) = rest.split_at_mut(d_out);
            flat = rest;
            (w, b)
        })
        .collect()
}

/// The layers over a flat parameter buffer `[W_0, b_0, …, W_o, b_o]` of the given
/// `[d_in, d_out]` shapes.
fn layers_of<'a, E>(mut flat: &'a [E], shapes: &[[usize; 2]]) -> Vec<Layer<'a, E>> {
    shapes
        .iter()
        .map(|&[d_in, d_out]| {
            let (w, rest) = flat.split_at(d_in * d_out);
            let (b, rest) = rest.split_at(d_out);
            flat = rest;
            Layer { w, b, d_in, d_out }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::jacobian::analytic::cpu::gemm::tests::noise;

    fn spec(shapes: &[[usize; 2]], omega: f64, dual: bool) -> OpSpec {
        OpSpec {
            shapes: shapes.to_vec(),
            omega,
            dual,
        }
    }

    /// `g_x` of the dual op (values and tangents) against central finite differences of
    /// `Σ R ⊙ out` in f64; the parameters' gradients are checked the same way, through
    /// the public API, in `tests/numerics_f64/analytic_f64.rs`.
    #[test]
    fn input_gradient_matches_finite_differences() {
        let (n, omega) = (5, 3.0);
        let shapes = [[4, 8], [8, 8], [8, 3]];
        let flat = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 4);
        let x = noise(n * 4, 5);
        for dual in [false, true] {
            let net = Net::new(&flat, &spec(&shapes, omega, dual));
            let rows = if dual { 4 * n } else { n };
            let r = noise(rows * 3, 6);
            let loss = |x: &[f64]| -> f64 {
                let (out, _) = net.forward(x);
                out.iter().zip(&r).map(|(a, b)| a * b).sum()
            };
            let (_, acts) = net.forward(&x);
            let mut g_params = vec![0.0; flat.len()];
            let g_x = net
                .backward(&acts, &x, &r, true, &mut g_params)
                .expect("asked for g_x");
            let h = 1e-6;
            for i in 0..x.len() {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[i] += h;
                down[i] -= h;
                let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                assert!(
                    (g_x[i] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "dual={dual} x[{i}]: {} vs {fd}",
                    g_x[i]
                );
            }
        }
    }

    /// The bias and first-layer gradients are sums over chunks of rows computed in
    /// parallel: they must not depend on how rayon splits the work, or fits stop being
    /// reproducible (a `reduce` made the same fit end 1e-4 apart from run to run).
    #[test]
    fn the_backward_is_bitwise_reproducible_across_runs() {
        let (n, omega) = (1000, 30.0);
        let shapes = [[4, 32], [32, 32], [32, 12]];
        let flat: Vec<f32> = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 7)
            .iter()
            .map(|&v| 0.1 * v as f32)
            .collect();
        let net = Net::new(&flat, &spec(&shapes, omega, true));
        let x: Vec<f32> = noise(n * 4, 8).iter().map(|&v| v as f32).collect();
        let g: Vec<f32> = noise(4 * n * 12, 9).iter().map(|&v| v as f32).collect();
        let run = || {
            let (_, acts) = net.forward(&x);
            let mut g_params = vec![0.0f32; flat.len()];
            net.backward(&acts, &x, &g, false, &mut g_params);
            g_params
        };
        let first = run();
        for _ in 0..20 {
            let again = run();
            assert!(
                first
                    .iter()
                    .zip(&again)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "the gradients changed between two runs"
            );
        }
    }

    /// Inside `serial` the op runs on the calling thread without splitting its GEMMs: the
    /// same outputs and gradients as the parallel op, up to the order of the split-K sums.
    #[test]
    fn the_serial_op_agrees_with_the_parallel_one() {
        let (n, shapes) = (700, [[4, 32], [32, 32], [32, 12]]);
        let flat: Vec<f32> = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 7)
            .iter()
            .map(|&v| 0.1 * v as f32)
            .collect();
        let net = Net::new(&flat, &spec(&shapes, 30.0, true));
        let x: Vec<f32> = noise(n * 4, 8).iter().map(|&v| v as f32).collect();
        let g: Vec<f32> = noise(4 * n * 12, 9).iter().map(|&v| v as f32).collect();
        let run = || {
            let (out, acts) = net.forward(&x);
            let mut g_params = vec![0.0f32; flat.len()];
            net.backward(&acts, &x, &g, false, &mut g_params);
            (out, g_params)
        };
        let (out, grad) = run();
        let (out_s, grad_s) = super::super::gemm::serial(run);
        assert_eq!(out, out_s, "the forward does not split its sums");
        let scale = grad.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (a, b) in grad.iter().zip(&grad_s) {
            assert!((a - b).abs() <= 1e-5 * scale, "{a} vs {b}");
        }
    }

    #[test]
    fn no_points_give_empty_outputs_and_zero_gradients() {
        let shapes = [[4, 8], [8, 8], [8, 3]];
        let flat = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 4);
        for dual in [false, true] {
            let net = Net::new(&flat, &spec(&shapes, 30.0, dual));
            let (out, acts) = net.forward(&[]);
            assert!(out.is_empty());
            let mut g = vec![1.0; flat.len()];
            let g_x = net.backward(&acts, &[], &[], true, &mut g);
            assert_eq!(g_x.map(|v| v.len()), Some(0));
            assert!(g.iter().all(|&v| v == 0.0), "no points, no gradient");
        }
    }
}
