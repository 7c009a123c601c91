//! Equivariance diagnostic: for a network `f` with input field types `X_i` and output type `Y`,
//! the relative error `‖f(g·x) − g·f(x)‖₂ / ‖f(x)‖₂` for every group element `g` that acts on
//! the pixel grid (all 8 of D4; the 4 quarter turns of C8). Used by the tests and meant for a
//! `equiarm nn check-equivariance CKPT` command on trained networks.
//!
//! Limitations: elements off the pixel grid (C8's 45° turns) are not measured; the inputs are
//! whatever the caller passes (random inputs in the tests; real observations give a more
//! honest figure for trained networks).

use crate::group::{Element, Group};
use crate::layers::transform;
use crate::nets::{EquiActor, EquiCritic, RotEquiNet, action_type, actor_out_type, lift_action};
use crate::repr::FieldType;
use burn::tensor::Tensor;
use equiarm_types::ACTION_DIM;

/// A network with a declared geometric interface.
pub trait Equivariant {
    /// The symmetry group.
    fn group(&self) -> Group;
    /// Field types of the inputs, in order.
    fn in_types(&self) -> Vec<FieldType>;
    /// Field type of the output.
    fn out_type(&self) -> FieldType;
    /// The network's geometric output `[B, out_type.size(), h, w]` for the given inputs.
    fn forward_geometric(&self, inputs: Vec<Tensor<4>>) -> Tensor<4>;
}

/// Relative equivariance error for one element.
#[derive(Clone, Debug)]
pub struct ElementError {
    /// The element.
    pub element: Element,
    /// `‖f(g·x) − g·f(x)‖₂ / ‖f(x)‖₂`.
    pub relative_error: f64,
}

fn norm(x: Tensor<4>) -> f64 {
    let v = x.into_data().try_to_vec::<f32>().expect("f32 tensor");
    v.iter().map(|&a| (a as f64) * (a as f64)).sum::<f64>().sqrt()
}

/// Measure the equivariance error of `net` on `inputs` for every grid element of its group.
pub fn equivariance_errors<N: Equivariant + ?Sized>(net: &N, inputs: Vec<Tensor<4>>) -> Vec<ElementError> {
    let in_types = net.in_types();
    let out_type = net.out_type();
    assert_eq!(in_types.len(), inputs.len(), "one input per input field type");
    let y = net.forward_geometric(inputs.clone());
    let scale = norm(y.clone()).max(1e-30);
    net.group()
        .grid_elements()
        .into_iter()
        .map(|g| {
            let gx: Vec<Tensor<4>> = inputs.iter().zip(&in_types).map(|(x, t)| transform(x.clone(), t, g)).collect();
            let lhs = net.forward_geometric(gx);
            let rhs = transform(y.clone(), &out_type, g);
            ElementError { element: g, relative_error: norm(lhs - rhs) / scale }
        })
        .collect()
}

impl Equivariant for EquiActor {
    fn group(&self) -> Group {
        Group::dihedral(4)
    }
    fn in_types(&self) -> Vec<FieldType> {
        vec![FieldType::trivial(self.group(), self.enc.convs[0].in_channels())]
    }
    fn out_type(&self) -> FieldType {
        actor_out_type(self.group())
    }
    fn forward_geometric(&self, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let y = self.forward_raw(inputs.into_iter().next().expect("one input"));
        let [b, c] = y.dims();
        y.reshape([b, c, 1, 1])
    }
}

impl Equivariant for EquiCritic {
    fn group(&self) -> Group {
        Group::dihedral(4)
    }
    /// Observation (trivial fields) and the lifted action ([`action_type`], 1×1).
    fn in_types(&self) -> Vec<FieldType> {
        vec![FieldType::trivial(self.group(), self.enc.convs[0].in_channels()), action_type(self.group())]
    }
    /// (Q1, Q2): two trivial fields.
    fn out_type(&self) -> FieldType {
        FieldType::trivial(self.group(), 2)
    }
    fn forward_geometric(&self, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let mut it = inputs.into_iter();
        let (obs, act) = (it.next().expect("obs"), it.next().expect("lifted action"));
        // The lifted action (p, dz, dx, dy, dθ, −dθ) back to (p, dx, dy, dz, dθ).
        let [b, _, _, _] = act.dims();
        let a: Tensor<2> = act.reshape([b, 6]);
        let col = |i: usize| a.clone().narrow(1, i, 1);
        let theta = (col(4) - col(5)).mul_scalar(0.5);
        let action = Tensor::cat(vec![col(0), col(2), col(3), col(1), theta], 1);
        let (q1, q2) = crate::nets::Critic::forward(self, obs, action);
        Tensor::cat(vec![q1, q2], 1).reshape([b, 2, 1, 1])
    }
}

impl Equivariant for RotEquiNet {
    fn group(&self) -> Group {
        Group::cyclic(8)
    }
    fn in_types(&self) -> Vec<FieldType> {
        vec![FieldType::trivial(self.group(), self.enc.convs[0].in_channels())]
    }
    fn out_type(&self) -> FieldType {
        FieldType::trivial(self.group(), 8)
    }
    fn forward_geometric(&self, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let y = self.forward(inputs.into_iter().next().expect("one input"));
        let [b, c] = y.dims();
        y.reshape([b, c, 1, 1])
    }
}

/// Lift a batch of actions for [`EquiCritic`]'s geometric interface (see [`lift_action`]).
pub fn lifted(action: Tensor<2>) -> Tensor<4> {
    lift_action(action)
}

/// Which network a checkpoint holds, for [`check_checkpoint`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetKind {
    /// [`EquiActor`].
    EquiActor,
    /// [`EquiCritic`].
    EquiCritic,
    /// [`RotEquiNet`].
    RotEqui,
}

impl std::str::FromStr for NetKind {
    type Err = UnknownNet;
    fn from_str(s: &str) -> Result<Self, UnknownNet> {
        match s {
            "equi-actor" => Ok(NetKind::EquiActor),
            "equi-critic" => Ok(NetKind::EquiCritic),
            "rot-equi" => Ok(NetKind::RotEqui),
            other => Err(UnknownNet(other.to_string())),
        }
    }
}

/// A word that names no [`NetKind`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown network `{0}`: expected equi-actor, equi-critic or rot-equi")]
pub struct UnknownNet(pub String);

/// Errors of [`check_checkpoint`].
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The network could not be built.
    #[error(transparent)]
    Net(#[from] crate::nets::NetError),
    /// The weights could not be loaded.
    #[error(transparent)]
    Checkpoint(#[from] crate::checkpoint::CheckpointError),
}

/// Load the weights in `path` (or keep the fresh seeded initialisation when `path` is `None`)
/// into a network of `kind` and `cfg`, and measure its equivariance
/// error per grid element on `batch` random N(0,1) inputs drawn with `seed` (and random tanh
/// actions for the critic). The body of `equiarm nn check-equivariance CKPT`.
pub fn check_checkpoint(
    kind: NetKind,
    cfg: &crate::nets::NetConfig,
    path: Option<&std::path::Path>,
    batch: usize,
    seed: u64,
    device: &burn::tensor::Device,
) -> Result<Vec<ElementError>, CheckError> {
    use crate::init::Init;
    fn load<M: burn::module::Module>(
        m: M,
        path: Option<&std::path::Path>,
    ) -> Result<M, crate::checkpoint::CheckpointError> {
        match path {
            Some(p) => crate::checkpoint::load(m, p),
            None => Ok(m),
        }
    }
    use burn::tensor::TensorData;
    let init = Init::new(seed);
    let s = cfg.input_size;
    let obs: Tensor<4> = Tensor::from_data(
        TensorData::new(init.normal("check.obs", batch * cfg.in_channels * s * s, 1.0), [batch, cfg.in_channels, s, s]),
        device,
    );
    Ok(match kind {
        NetKind::EquiActor => equivariance_errors(&load(EquiActor::new(cfg, &init, device)?, path)?, vec![obs]),
        NetKind::RotEqui => equivariance_errors(&load(RotEquiNet::new(cfg, &init, device)?, path)?, vec![obs]),
        NetKind::EquiCritic => {
            let act: Tensor<2> = Tensor::from_data(
                TensorData::new(init.normal("check.act", batch * ACTION_DIM, 1.0), [batch, ACTION_DIM]),
                device,
            );
            equivariance_errors(&load(EquiCritic::new(cfg, &init, device)?, path)?, vec![obs, lifted(act.tanh())])
        }
    })
}
