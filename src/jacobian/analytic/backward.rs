//! The hand-written backward of the analytic sine layer (DESIGN §2):
//! with `G_Z = ∂L/∂(S W)` from [`super::SirenBackend::sine_dual_activation_backward`],
//! `g_W = Sᵀ G_Z`, `g_b = Σ_rows G_Z[0..N]` and `g_S = G_Z Wᵀ`.

use burn::backend::autodiff::{
    Autodiff, NodeId,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::{Slice, TensorMetadata, tensor::FloatTensor};
use burn::tensor::Shape;

use super::SirenBackend;

/// The backward of a sine layer; `dual` says whether its input stacks values and
/// tangents (`sine_dual_layer`) or holds values only (`sine_layer`).
#[derive(Debug)]
struct SineLayerBackward {
    dual: bool,
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
        let stacked: FloatTensor<B> = checkpointer.retrieve_node_output(s_id);
        let weight: FloatTensor<B> = checkpointer.retrieve_node_output(w_id);
        let bias: FloatTensor<B> = checkpointer.retrieve_node_output(b_id);
        let [r, d] = zs.shape().dims::<2>();
        let (g_zs, value_rows) = if self.dual {
            (
                B::sine_dual_activation_backward(zs, bias, grad, omega),
                r / 4,
            )
        } else {
            (B::sine_activation_backward(zs, bias, grad, omega), r)
        };
        if let Some(node) = node_b {
            // The bias enters the values only; tangents do not see it.
            let g_z = B::float_slice(
                g_zs.clone(),
                &[Slice::from(0..value_rows), Slice::from(0..d)],
            );
            let g_b = B::float_reshape(B::float_sum_dim(g_z, 0), Shape::new([d]));
            grads.register::<B>(node.id, g_b);
        }
        if let Some(node) = node_w {
            let g_w = B::float_matmul(B::float_transpose(stacked), g_zs.clone());
            grads.register::<B>(node.id, g_w);
        }
        if let Some(node) = node_s {
            let g_s = B::float_matmul(g_zs, B::float_transpose(weight));
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
    dual: bool,
) -> FloatTensor<Autodiff<B, C>> {
    match (SineLayerBackward { dual })
        .prepare::<C>([input.node(), weight.node(), bias.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let s_id = prep.checkpoint(&input);
            let w_id = prep.checkpoint(&weight);
            let b_id = prep.checkpoint(&bias);
            let zs = B::float_matmul(input.into_primitive(), weight.into_primitive());
            let bias = bias.into_primitive();
            let out = if dual {
                B::sine_dual_activation(zs.clone(), bias, omega)
            } else {
                B::sine_activation(zs.clone(), bias, omega)
            };
            prep.finish((s_id, w_id, b_id, zs, omega), out)
        }
        OpsKind::UnTracked(prep) => {
            let (input, weight, bias) = (
                input.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            );
            let out = if dual {
                B::sine_dual_layer(input, weight, bias, omega)
            } else {
                B::sine_layer(input, weight, bias, omega)
            };
            prep.finish(out)
        }
    }
}

impl<B: SirenBackend, C: CheckpointStrategy> SirenBackend for Autodiff<B, C> {
    fn sine_dual_layer(
        stacked: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(stacked, weight, bias, omega, true)
    }

    fn sine_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(input, weight, bias, omega, false)
    }
}
