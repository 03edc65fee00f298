//! The whole SIREN on the `Autodiff` graph: one node, with the input and the flat
//! parameters as its parents, whose backward is [`super::SirenOps::siren_backward`], the
//! hand-written backward of DESIGN §2.

use burn::backend::autodiff::{
    Autodiff,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::tensor::FloatTensor;

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

impl<B: SirenOps, C: CheckpointStrategy> SirenBackend for Autodiff<B, C> {
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
