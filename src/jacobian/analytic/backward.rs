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

/// The backward of the first dual sine layer
/// ([`super::SirenBackend::sine_dual_input_layer`]). With `G = [G_z; G_ż]` the activation's
/// backward: `g_b = Σ_rows G_z`, `g_X = G_z Wᵀ`, and
/// `g_W = Xᵀ G_z + [Σ_rows G_ż,x; Σ_rows G_ż,y; Σ_rows G_ż,z; 0]`, the second term being
/// the seeds' part `Σ_k e_kᵀ G_ż,k` of `S_0ᵀ G` without building `S_0`.
#[derive(Debug)]
struct InputLayerBackward;

impl<B: SirenBackend> Backward<B, 3> for InputLayerBackward {
    /// `X`, `W` and `b` (checkpointed), `z_v = X W`, and `ω`.
    type State = (NodeId, NodeId, NodeId, FloatTensor<B>, f64);

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [node_x, node_w, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (x_id, w_id, b_id, zv, omega) = ops.state;
        let input: FloatTensor<B> = checkpointer.retrieve_node_output(x_id);
        let weight: FloatTensor<B> = checkpointer.retrieve_node_output(w_id);
        let bias: FloatTensor<B> = checkpointer.retrieve_node_output(b_id);
        let [n, d] = zv.shape().dims::<2>();
        let g = B::sine_dual_input_activation_backward(zv, weight.clone(), bias, grad, omega);
        let g_z = B::float_slice(g.clone(), &[Slice::from(0..n), Slice::from(0..d)]);
        if let Some(node) = node_b {
            let g_b = B::float_reshape(B::float_sum_dim(g_z.clone(), 0), Shape::new([d]));
            grads.register::<B>(node.id, g_b);
        }
        if let Some(node) = node_w {
            let g_w = B::float_matmul(B::float_transpose(input), g_z.clone());
            let tangents = B::float_reshape(
                B::float_slice(g, &[Slice::from(n..4 * n), Slice::from(0..d)]),
                Shape::new([3, n, d]),
            );
            let seeds = B::float_reshape(B::float_sum_dim(tangents, 1), Shape::new([3, d]));
            let top = [Slice::from(0..3), Slice::from(0..d)];
            let sum = B::float_add(B::float_slice(g_w.clone(), &top), seeds);
            grads.register::<B>(node.id, B::float_slice_assign(g_w, &top, sum));
        }
        if let Some(node) = node_x {
            grads.register::<B>(node.id, B::float_matmul(g_z, B::float_transpose(weight)));
        }
    }
}

/// Records the first dual sine layer on the autodiff graph with [`InputLayerBackward`].
fn tracked_input_layer<B: SirenBackend, C: CheckpointStrategy>(
    input: FloatTensor<Autodiff<B, C>>,
    weight: FloatTensor<Autodiff<B, C>>,
    bias: FloatTensor<Autodiff<B, C>>,
    omega: f64,
) -> FloatTensor<Autodiff<B, C>> {
    match InputLayerBackward
        .prepare::<C>([input.node(), weight.node(), bias.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let x_id = prep.checkpoint(&input);
            let w_id = prep.checkpoint(&weight);
            let b_id = prep.checkpoint(&bias);
            let weight = weight.into_primitive();
            let zv = B::float_matmul(input.into_primitive(), weight.clone());
            let out =
                B::sine_dual_input_activation(zv.clone(), weight, bias.into_primitive(), omega);
            prep.finish((x_id, w_id, b_id, zv, omega), out)
        }
        OpsKind::UnTracked(prep) => prep.finish(B::sine_dual_input_layer(
            input.into_primitive(),
            weight.into_primitive(),
            bias.into_primitive(),
            omega,
        )),
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

impl<B: SirenOps + SirenBackend, C: CheckpointStrategy> SirenBackend for Autodiff<B, C> {
    fn sine_dual_input_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_input_layer::<B, C>(input, weight, bias, omega)
    }

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
