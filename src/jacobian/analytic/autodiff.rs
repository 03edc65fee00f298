//! The analytic op on Burn's `Autodiff` graph, with the hand-written backward of
//! docs/design.md §2.2: the whole network as one node ([`SirenBackend::siren`], the CPU
//! path), whose backward is [`SirenOps::siren_backward`]; or one node per sine layer
//! ([`SirenBackend::sine_dual_layer`], the wgpu path), whose backward is the activation's
//! backward, `g_W = Sᵀ G_Z`, `g_b = Σ_rows G_Z[0..N]` and `g_S = G_Z Wᵀ`; the first of them
//! from the input without its seeds ([`SirenBackend::sine_dual_input_layer`]).

use burn::backend::autodiff::{
    Autodiff, NodeId,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::{Slice, TensorMetadata, tensor::FloatTensor};
use burn::tensor::Shape;

use super::{OpSpec, SineKernel, SirenBackend, SirenOps, sine_pass};

/// The whole network as one node; its parents are the input and the flat parameters.
#[derive(Debug)]
struct SirenBackward;

/// What the whole-network node keeps for its backward.
#[derive(Clone, Debug)]
struct SirenState<B: SirenOps> {
    /// The backend's saved activations.
    saved: B::Saved,
    input: FloatTensor<B>,
    /// The flat parameters (see [`SirenOps`]).
    params: FloatTensor<B>,
    spec: OpSpec,
}

impl<B: SirenOps> Backward<B, 2> for SirenBackward {
    type State = SirenState<B>;

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad = grads.consume::<B>(&ops.node);
        let SirenState {
            saved,
            input,
            params,
            spec,
        } = ops.state;
        let [input_node, params_node] = ops.parents;
        let (g_input, g_params) =
            B::siren_backward(saved, input, params, &spec, grad, input_node.is_some());
        if let (Some(node), Some(g)) = (input_node, g_input) {
            grads.register::<B>(node.id, g);
        }
        if let Some(node) = params_node {
            grads.register::<B>(node.id, g_params);
        }
    }
}

/// The backward of a sine layer with input `S`, pre-activation `zs = S W` and the
/// activation's backward `G` (`G_z`: its value rows): `g_b = Σ_rows G_z`, `g_W = Sᵀ G`,
/// `g_S = G Wᵀ`. For the first dual layer ([`SineKernel::DualInputForward`]), `S` is the
/// input `X` alone: `g_W = Xᵀ G_z + [Σ_rows G_ż,x; Σ_rows G_ż,y; Σ_rows G_ż,z; 0]`, the
/// second term being the seeds' part `Σ_k e_kᵀ G_ż,k` of `S_0ᵀ G` without building `S_0`,
/// and `g_X = G_z Wᵀ`.
#[derive(Debug)]
struct SineLayerBackward {
    /// The layer's forward pass: [`SineKernel::Forward`] (values only),
    /// [`SineKernel::DualForward`] (stacked values and tangents) or
    /// [`SineKernel::DualInputForward`] (the network's input, whose tangents are the
    /// seeds, not built).
    layer: SineKernel,
}

/// What a sine-layer node keeps for its backward.
#[derive(Clone, Debug)]
struct SineLayerState<B: SirenBackend> {
    /// The checkpointed input `S`, weight `W` and bias `b`.
    input: NodeId,
    weight: NodeId,
    bias: NodeId,
    /// The pre-activation `zs = S W`.
    zs: FloatTensor<B>,
    omega: f64,
}

impl<B: SirenBackend> Backward<B, 3> for SineLayerBackward {
    type State = SineLayerState<B>;

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [node_s, node_w, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let SineLayerState {
            input: s_id,
            weight: w_id,
            bias: b_id,
            zs,
            omega,
        } = ops.state;
        let input: FloatTensor<B> = checkpointer.retrieve_node_output(s_id);
        let weight: FloatTensor<B> = checkpointer.retrieve_node_output(w_id);
        let bias: FloatTensor<B> = checkpointer.retrieve_node_output(b_id);
        let [r, d] = zs.shape().dims::<2>();
        let rows = |t: FloatTensor<B>, from: usize, to: usize| {
            B::float_slice(t, &[Slice::from(from..to), Slice::from(0..d)])
        };
        let seeded = self.layer == SineKernel::DualInputForward;
        let value_rows = if self.layer == SineKernel::DualForward {
            r / 4
        } else {
            r
        };
        let g = sine_pass::<B>(
            self.layer.backward(),
            zs,
            bias,
            Some(grad),
            Some(weight.clone()),
            omega,
        );
        // The rows of G that meet S in `zs = S W`: all of them, except for the first layer,
        // whose tangent rows met the seeds.
        let g_s_rows = if seeded {
            rows(g.clone(), 0, value_rows)
        } else {
            g.clone()
        };
        if let Some(node) = node_b {
            // The bias enters the values only; tangents do not see it.
            let g_z = rows(g.clone(), 0, value_rows);
            let g_b = B::float_reshape(B::float_sum_dim(g_z, 0), Shape::new([d]));
            grads.register::<B>(node.id, g_b);
        }
        if let Some(node) = node_w {
            let mut g_w = B::float_matmul(B::float_transpose(input), g_s_rows.clone());
            if seeded {
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

/// Records a sine layer, whose forward pass is `layer`, on the autodiff graph with
/// [`SineLayerBackward`] as its backward.
fn tracked_layer<B: SirenBackend, C: CheckpointStrategy>(
    input: FloatTensor<Autodiff<B, C>>,
    weight: FloatTensor<Autodiff<B, C>>,
    bias: FloatTensor<Autodiff<B, C>>,
    omega: f64,
    layer: SineKernel,
) -> FloatTensor<Autodiff<B, C>> {
    match (SineLayerBackward { layer })
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
            let out = sine_pass::<B>(layer, zs.clone(), bias, None, Some(weight), omega);
            let state = SineLayerState {
                input: s_id,
                weight: w_id,
                bias: b_id,
                zs,
                omega,
            };
            prep.finish(state, out)
        }
        OpsKind::UnTracked(prep) => {
            let (input, weight, bias) = (
                input.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            );
            prep.finish(match layer {
                SineKernel::Forward => B::sine_layer(input, weight, bias, omega),
                SineKernel::DualInputForward => {
                    B::sine_dual_input_layer(input, weight, bias, omega)
                }
                _ => B::sine_dual_layer(input, weight, bias, omega),
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
        tracked_layer::<B, C>(input, weight, bias, omega, SineKernel::DualInputForward)
    }

    fn sine_dual_layer(
        stacked: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(stacked, weight, bias, omega, SineKernel::DualForward)
    }

    fn sine_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        tracked_layer::<B, C>(input, weight, bias, omega, SineKernel::Forward)
    }

    fn siren(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: OpSpec,
    ) -> FloatTensor<Self> {
        match SirenBackward
            .prepare::<C>([input.node(), params.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (input, params) = (input.into_primitive(), params.into_primitive());
                let (out, saved) = B::siren_forward(input.clone(), params.clone(), &spec);
                let state = SirenState {
                    saved,
                    input,
                    params,
                    spec,
                };
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => {
                let (input, params) = (input.into_primitive(), params.into_primitive());
                let (out, _) = B::siren_forward(input, params, &spec);
                prep.finish(out)
            }
        }
    }
}
