//! Adam (PyTorch's update, no weight decay) and the Polyak target update, keyed by parameter
//! *path* (`enc.convs.0.weight.0`), not by burn's random `ParamId`, so optimiser state saved by one
//! process loads into a network rebuilt by another (`--resume`, checkpoints).
//!
//! State files are safetensors (`{path}.m`, `{path}.v` as F32, the step count in the metadata), the
//! same format as the weights, readable by any safetensors tool.
//!
//! Limitations: F32 parameters only; one learning rate per optimiser.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use equiarm_nn::burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use equiarm_nn::burn::optim::GradientsParams;
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_types::files::{FileError, at};
use thiserror::Error;

/// Errors saving or loading optimiser state.
#[derive(Debug, Error)]
pub enum OptimError {
    /// Reading or writing the file failed (the file, and the cause).
    #[error(transparent)]
    File(#[from] FileError),
    /// The file is not a valid state file for this network.
    #[error("{path}: {message}")]
    Format {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Adam hyper-parameters (PyTorch defaults except the learning rate).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// Learning rate (docs/paper.md §2: 1e-3).
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator epsilon.
    pub eps: f64,
}

impl AdamParams {
    /// PyTorch's defaults with learning rate `lr`.
    pub fn new(lr: f64) -> Self {
        AdamParams { lr, beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// Adam over one module: moments per parameter path.
#[derive(Clone, Debug)]
pub struct Adam {
    params: AdamParams,
    step: u64,
    moments: BTreeMap<String, (Vec<usize>, Tensor<1>, Tensor<1>)>,
}

impl Adam {
    /// A fresh optimiser.
    pub fn new(params: AdamParams) -> Self {
        Adam { params, step: 0, moments: BTreeMap::new() }
    }

    /// A fresh optimiser holding zero moments for every parameter of `module` (on `device`, the
    /// module's device without autodiff): it steps exactly as [`Adam::new`] (absent moments start
    /// at zero), but its saved state covers every parameter, so it loads back even for a module
    /// some of whose parameters never get a gradient (FERM's actor convs, which are the critic's; the
    /// critic's Q heads under the contrastive loss).
    pub fn covering<M: Module>(params: AdamParams, module: &M, device: &Device) -> Self {
        let moments = equiarm_nn::checkpoint::parameter_shapes(module)
            .into_iter()
            .map(|(name, shape)| {
                let n: usize = shape.iter().product();
                (name, (shape, Tensor::zeros([n], device), Tensor::zeros([n], device)))
            })
            .collect();
        Adam { params, step: 0, moments }
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Set the step size of the following steps.
    pub fn set_lr(&mut self, lr: f64) {
        self.params.lr = lr;
    }

    /// One Adam step on `module` with `grads` (from `GradientsParams::from_grads`); parameters
    /// without a gradient are left unchanged.
    pub fn step<M: Module>(&mut self, module: M, grads: GradientsParams) -> M {
        self.step += 1;
        let t = self.step as i32;
        let p = self.params;
        let mut mapper = AdamMapper {
            path: Vec::new(),
            grads,
            moments: &mut self.moments,
            p,
            bc1: 1.0 - p.beta1.powi(t),
            bc2: 1.0 - p.beta2.powi(t),
        };
        module.map(&mut mapper)
    }

    /// Save the moments and the step count to a safetensors file.
    pub fn save(&self, path: &Path) -> Result<(), OptimError> {
        let mut tensors = Vec::new();
        for (name, (shape, m, v)) in &self.moments {
            tensors.push((format!("{name}.m"), shape.clone(), to_vec(m.clone())));
            tensors.push((format!("{name}.v"), shape.clone(), to_vec(v.clone())));
        }
        let meta = [("step".to_string(), self.step.to_string()), ("lr".to_string(), self.params.lr.to_string())];
        Ok(crate::tensorfile::write(path, &tensors, &meta)?)
    }

    /// Load state saved by [`Adam::save`] for `module` (every moment must name one of its
    /// parameters with the same shape), the moments on `device` (the module's device, without
    /// autodiff).
    pub fn load<M: Module>(params: AdamParams, module: &M, path: &Path, device: &Device) -> Result<Self, OptimError> {
        let fmt = |message: String| OptimError::Format { path: path.into(), message };
        let file = crate::tensorfile::read(path).map_err(|e| match e {
            crate::tensorfile::ReadError::Io(source) => OptimError::File(at(path)(source)),
            crate::tensorfile::ReadError::Format(m) => fmt(m),
        })?;
        let step: u64 = file
            .meta
            .get("step")
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| fmt("metadata has no valid `step`".into()))?;
        let shapes: BTreeMap<String, Vec<usize>> =
            equiarm_nn::checkpoint::parameter_shapes(module).into_iter().collect();
        let mut moments = BTreeMap::new();
        let mut by_name: BTreeMap<String, (Vec<usize>, Vec<f32>)> =
            file.tensors.into_iter().map(|(n, s, d)| (n, (s, d))).collect();
        for (name, shape) in &shapes {
            let m = by_name.remove(&format!("{name}.m"));
            let v = by_name.remove(&format!("{name}.v"));
            match (m, v) {
                (Some((sm, dm)), Some((sv, dv))) => {
                    if &sm != shape || &sv != shape {
                        return Err(fmt(format!("moments of `{name}` have shape {sm:?}, the network needs {shape:?}")));
                    }
                    let n = dm.len();
                    moments.insert(
                        name.clone(),
                        (
                            shape.clone(),
                            Tensor::from_data(TensorData::new(dm, [n]), device),
                            Tensor::from_data(TensorData::new(dv, [n]), device),
                        ),
                    );
                }
                (None, None) if step == 0 => {}
                _ => return Err(fmt(format!("no moments for parameter `{name}`: saved for another network"))),
            }
        }
        if let Some(extra) = by_name.keys().next() {
            return Err(fmt(format!("tensor `{extra}` belongs to no parameter of this network")));
        }
        Ok(Adam { params, step, moments })
    }
}

fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

struct AdamMapper<'a> {
    path: Vec<String>,
    grads: GradientsParams,
    moments: &'a mut BTreeMap<String, (Vec<usize>, Tensor<1>, Tensor<1>)>,
    p: AdamParams,
    bc1: f64,
    bc2: f64,
}

impl ModuleMapper for AdamMapper<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let (id, tensor, mapper) = param.consume();
        let Some(grad) = self.grads.remove::<D>(id) else {
            return Param::from_mapped_value(id, tensor, mapper);
        };
        let name = self.path.join(".");
        let shape: Vec<usize> = tensor.dims().to_vec();
        let n: usize = shape.iter().product();
        let device = tensor.device();
        let require_grad = tensor.is_require_grad();
        let g: Tensor<1> = grad.inner().reshape([n]);
        // New moments live where the gradient does: the agent's device, without autodiff.
        let plain_device = g.device();
        let (m, v) = match self.moments.remove(&name) {
            Some((_, m, v)) => (m, v),
            None => (Tensor::zeros([n], &plain_device), Tensor::zeros([n], &plain_device)),
        };
        let p = self.p;
        let m = m.mul_scalar(p.beta1) + g.clone().mul_scalar(1.0 - p.beta1);
        let v = v.mul_scalar(p.beta2) + g.powf_scalar(2.0).mul_scalar(1.0 - p.beta2);
        // PyTorch: p -= lr / bc1 * m / (sqrt(v) / sqrt(bc2) + eps)
        let denom = v.clone().sqrt().div_scalar(self.bc2.sqrt()).add_scalar(p.eps);
        let delta = m.clone().div(denom).mul_scalar(p.lr / self.bc1);
        let w: Tensor<1> = tensor.inner().reshape([n]) - delta;
        self.moments.insert(name, (shape.clone(), m, v));
        let mut w: Tensor<D> = w.reshape::<D, _>(shape_array::<D>(&shape));
        if device.is_autodiff() {
            w = Tensor::from_inner(w);
        }
        if require_grad {
            w = w.require_grad();
        }
        Param::from_mapped_value(id, w, mapper)
    }
}

fn shape_array<const D: usize>(shape: &[usize]) -> [usize; D] {
    let mut a = [0; D];
    a.copy_from_slice(shape);
    a
}

/// Adam on one scalar (the SAC temperature `log α`), in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScalarAdam {
    params: AdamParams,
    /// Steps taken.
    pub step: u64,
    /// First moment.
    pub m: f64,
    /// Second moment.
    pub v: f64,
}

impl ScalarAdam {
    /// Fresh state.
    pub fn new(params: AdamParams) -> Self {
        ScalarAdam { params, step: 0, m: 0.0, v: 0.0 }
    }

    /// Restore saved moments.
    pub fn with_state(params: AdamParams, step: u64, m: f64, v: f64) -> Self {
        ScalarAdam { params, step, m, v }
    }

    /// Set the step size of the following steps.
    pub fn set_lr(&mut self, lr: f64) {
        self.params.lr = lr;
    }

    /// `x − Adam(grad)`.
    pub fn step(&mut self, x: f64, grad: f64) -> f64 {
        self.step += 1;
        let p = self.params;
        self.m = p.beta1 * self.m + (1.0 - p.beta1) * grad;
        self.v = p.beta2 * self.v + (1.0 - p.beta2) * grad * grad;
        let bc1 = 1.0 - p.beta1.powi(self.step as i32);
        let bc2 = 1.0 - p.beta2.powi(self.step as i32);
        x - p.lr / bc1 * self.m / ((self.v).sqrt() / bc2.sqrt() + p.eps)
    }
}

/// Every float parameter of `module` by path, on the plain (non-autodiff) device.
pub fn parameters<M: Module>(module: &M) -> BTreeMap<String, Tensor<1>> {
    struct Collect {
        path: Vec<String>,
        out: BTreeMap<String, Tensor<1>>,
    }
    impl ModuleVisitor for Collect {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let t = param.val().inner();
            let n: usize = t.dims().iter().product();
            self.out.insert(self.path.join("."), t.reshape([n]));
        }
    }
    let mut c = Collect { path: Vec::new(), out: BTreeMap::new() };
    module.visit(&mut c);
    c.out
}

/// Polyak averaging `target ← (1 − τ)·target + τ·online` for every parameter path the two share
/// (docs/paper.md §2: τ = 0.01 after every update). `target` lives on the plain device.
pub fn polyak<M: Module>(target: M, online: &M, tau: f64) -> M {
    polyak_by(target, online, &|_| tau)
}

/// [`polyak`] with a coefficient per parameter path (FERM: its encoder at 0.05, the heads at τ).
pub fn polyak_by<M: Module>(target: M, online: &M, tau_of: &dyn Fn(&str) -> f64) -> M {
    struct Mix<'a> {
        path: Vec<String>,
        online: BTreeMap<String, Tensor<1>>,
        tau_of: &'a dyn Fn(&str) -> f64,
    }
    impl ModuleMapper for Mix<'_> {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let (id, tensor, mapper) = param.consume();
            let path = self.path.join(".");
            let Some(o) = self.online.remove(&path) else {
                return Param::from_mapped_value(id, tensor, mapper);
            };
            let tau = (self.tau_of)(&path);
            let dims = tensor.dims();
            let mixed = tensor.mul_scalar(1.0 - tau) + o.reshape::<D, _>(dims).mul_scalar(tau);
            Param::from_mapped_value(id, mixed, mapper)
        }
    }
    target.map(&mut Mix { path: Vec::new(), online: parameters(online), tau_of })
}
