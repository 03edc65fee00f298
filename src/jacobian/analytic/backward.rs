//! The analytic SIREN on the `Autodiff` graph, with the hand-written backward of DESIGN §2:
//! the whole network as one node ([`super::SirenBackend::siren`], the CPU path), whose
//! backward is [`super::SirenOps::siren_backward`]; or one node per sine layer
//! ([`super::SirenBackend::sine_dual_layer`], the wgpu path), whose backward is the
//! activation's backward, `g_W = Sᵀ G_Z`, `g_b = Σ_rows G_Z[0..N]` and `g_S = G_Z Wᵀ`; the
//! first of them from the input without its seeds
//! ([`super::SirenBackend::sine_dual_input_layer`]).

use burn::backend::autodiff::{
    Autodiff, NodeId,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::{Slice, TensorMetadata, tensor::FloatTensor};
use burn::tensor::Shape;

use super::{SirenBackend, SirenOps};

#[derive(Debug)]
struct SirenBackward {
    dual: bool,
}

impl<B: SirenOps> Backward<B, 2> for SirenBackward {
    /// The saved activations, the input, the flat parameters, the layer shapes and `ω`.
    type State = (
        B::Saved,
        FloatTensor<B>,
        FloatTensor<B>,
        Vec<[usize; 2]>,
        f64,
    );

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad = grads.consume::<B>(&ops.node);
        let (saved, input, params, shapes, omega) = ops.state;
        let [input_node, params_node] = ops.parents;
        let (g_input, g_params) = B::siren_backward(
            saved,
            input,
            params,
            &shapes,
            grad,
            omega,
            self.dual,
            input_node.is_some(),
        );
        if let (Some(node), Some(g)) = (input_node, g_input) {
            grads.register::<B>(node.id, g);
        }
        if let Some(node) = params_node {
            grads.register::<B>(node.id, g_params);
        }
    }
}

/// What a sine layer's input holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LayerInput {
    /// Values only (`sine_layer`).
    Values,
    /// Values and their tangents, stacked (`sine_dual_layer`).
    Stacked,
    /// The network's input, whose tangents are the seeds `e_x, e_y, e_z`, not built
    /// (`sine_dual_input_layer`).
    Seeded,
}

/// The backward of a sine layer with input `S`, pre-activation `zs = S W` and the
/// activation's backward `G` (`G_z`: its value rows): `g_b = Σ_rows G_z`, `g_W = Sᵀ G`,
/// `g_S = G Wᵀ`. For the [`LayerInput::Seeded`] first layer, `S` is the input `X` alone:
/// `g_W = Xᵀ G_z + [Σ_rows G_ż,x; Σ_rows G_ż,y; Σ_rows G_ż,z; 0]`, the second term being the
/// seeds' part `Σ_k e_kᵀ G_ż,k` of `S_0ᵀ G` without building `S_0`, and `g_X = G_z Wᵀ`.
#[derive(Debug)]
struct SineLayerBackward {
    input: LayerInput,
}

impl<B: SirenBackend> Backward<B, 3> for SineLayerBackward {
    /// `S`, `W` and `b` (checkpointed), `zs = S W`, and `ω`.
    type State = (NodeId, NodeId, NodeId, FloatTensor<B>, f64);

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [node_s, node_w, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (s_id, w_id, b_id, zs, omega) = ops.state;
        let input: FloatTensor<B> = checkpointer.retrieve_node_output(s_id);
        let weight: FloatTensor<B> = checkpointer.retrieve_node_output(w_id);
        let bias: FloatTensor<B> = checkpointer.retrieve_node_output(b_id);
        let [r, d] = zs.shape().dims::<2>();
        let rows = |t: FloatTensor<B>, from: usize, to: usize| {
            B::float_slice(t, &[Slice::from(from..to), Slice::from(0..d)])
        };
        let (g, value_rows) = match self.input {
            LayerInput::Values => (B::sine_activation_backward(zs, bias, grad, omega), r),
            LayerInput::Stacked => (
                B::sine_dual_activation_backward(zs, bias, grad, omega),
                r / 4,
            ),
            LayerInput::Seeded => (
                B::sine_dual_input_activation_backward(zs, weight.clone(), bias, grad, omega),
                r,
            ),
        };
        // The rows of G that meet S in `zs = S W`: all of them, except for the first layer,
        // whose tangent rows met the seeds.
        let g_s_rows = match self.input {
            LayerInput::Seeded => rows(g.clone(), 0, value_rows),
            _ => g.clone(),
        };
        if let Some(node) = node_b {
            // The bias enters the values only; tangents do not see it.
            let g_z = rows(g.clone(), 0, value_rows);
            let g_b = B::float_reshape(B::float_sum_dim(g_z, 0), Shape::new([d]));
            grads.register::<B>(node.id, g_b);
        }
        if let Some(node) = node_w {
            let mut g_w = B::float_matmul(B::float_transpose(input), g_s_rows.clone());
            if self.input == LayerInput::Seeded {
                let n = value_rows;
                let tangents = B::float_reshape(rows(g, n, 4 * n), Shape::new([3, n, d]));
                let seeds = B::float_reshape(B::float_sum_dim(tangents, 1), Shape::new([3, d]));
                let top = [Slice::from(0..3), Slice::from(0..d)];
                let sum = B::float_add(B::float_slice(g_w.clone(), &top), seeds);
                g_w = B::float_slice_assign(g_w, &top, sum);
            }
            grads.register::<B>(node.id, g_w);
        }
        if let Some(node) = node_s {
            let g_s = B::float_matmul(g_s_rows, B::float_transpose(weight));
            grads.register::<B>(node.id, g_s);
        }
    }
}

/// Records a sine layer on the autodiff graph with [`SineLayerBackward`] as its backward.
fn tracked_layer<B: SirenBackend, C: CheckpointStrategy>(
    input: FloatTensor<Autodiff<B, C>>,
    weight: FloatTensor<Autodiff<B, C>>,
    bias: FloatTensor<Autodiff<B, C>>,
    omega: f64,
    kind: LayerInput,
) -> FloatTensor<Autodiff<B, C>> {
    match (SineLayerBackward { input: kind })
        .prepare::<C>([input.node(), weight.node(), bias.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let s_id = prep.checkpoint(&input);
            let w_id = prep.checkpoint(&weight);
            let b_id = prep.checkpoint(&bias);
            let weight = weight.into_primitive();
            let zs = B::float_matmul(input.into_primitive(), weight.clone());
            let bias = bias.into_primitive();
            let out = match kind {
                LayerInput::Values => B::sine_activation(zs.clone(), bias, omega),
                LayerInput::Stacked => B::sine_dual_activation(zs.clone(), bias, omega),
                LayerInput::Seeded => {
                    B::sine_dual_input_activation(zs.clone(), weight, bias, omega)
                }
            };
            prep.finish((s_id, w_id, b_id, zs, omega), out)
        }
        OpsKind::UnTracked(prep) => {
            let (input, weight, bias) = (
                input.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            );
            prep.finish(match kind {
                LayerInput::Values => B::sine_layer(input, weight, bias, omega),
                LayerInput::Stacked => B::sine_dual_layer(input, weight, bias, omega),
                LayerInput::Seeded => B::sine_dual_input_layer(input, weight, bias, omega),
            })
        }
    }
}

impl<B: SirenOps + SirenBackend, C: CheckpointStrategy> SirenBackend for Autodiff<B, C> {
    fn sine_dual_input_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(input, weight, bias, omega, LayerInput::Seeded)
    }

    fn sine_dual_layer(
        stacked: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(stacked, weight, bias, omega, LayerInput::Stacked)
    }

    fn sine_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(input, weight, bias, omega, LayerInput::Values)
    }

    fn siren(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        shapes: Vec<[usize; 2]>,
        omega: f64,
        dual: bool,
    ) -> FloatTensor<Self> {
        let backward = SirenBackward { dual };
        match backward
            .prepare::<C>([input.node(), params.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (input, params) = (input.into_primitive(), params.into_primitive());
                let (out, saved) =
                    B::siren_forward(input.clone(), params.clone(), &shapes, omega, dual);
                prep.finish((saved, input, params, shapes, omega), out)
            }
            OpsKind::UnTracked(prep) => {
                let (input, params) = (input.into_primitive(), params.into_primitive());
                let (out, _) = B::siren_forward(input, params, &shapes, omega, dual);
                prep.finish(out)
            }
        }
    }
}
