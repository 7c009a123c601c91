//! equiarm_nn: equivariant neural networks for robot learning, after Wang et al. (ICLR 2023),
//! "The Surprising Effectiveness of Equivariant Models in Domains with Latent Symmetry".
//!
//! - [`group`]: the groups `C_n` / `D_n` and their action on the plane and the pixel grid.
//! - [`repr`]: representations (trivial, regular, irreducible, quotient) and field types.
//! - [`basis`]: the generic equivariant kernel basis solver (e2cnn's `R2Conv` function space).
//! - [`kernels`]: our convolution forward and backward (im2col + GEMM, bias and ReLU fused) as a
//!   custom op of the `flex` backend.
//! - [`layers`]: equivariant conv, ReLU, max-pool, group pooling, concatenation, group action.
//! - [`nets`]: the paper's networks (Equi / CNN / SEN SAC actor and critic, rotation nets).
//! - [`checkpoint`]: safetensors save / load with readable names and architecture checks.
//! - [`diagnostics`]: per-group-element equivariance error of a network.
//! - [`device`]: the device by name (`cpu`; `vulkan[:N|:cpu]` in the GPU build, the `vulkan` feature), checked before use.
//!
//! Tensors are burn 0.22 tensors; the default backend is `flex` (pure Rust CPU):
//!
//! ```no_run
//! use equiarm_nn::{burn::tensor::{Device, Tensor}, init::Init, nets::{Actor, EquiActor, NetConfig}};
//! let device = Device::flex();
//! let actor = EquiActor::new(&NetConfig::reduced_cpu(), &Init::new(0), &device).unwrap();
//! let obs = Tensor::<4>::zeros([1, equiarm_types::OBS_PLANES, 64, 64], &device);
//! let (mean, log_std) = actor.forward(obs);
//! ```
//!
//! Limitations: no ROS here; stride-1 convolutions with 1×1 and 3×3 kernels only; image-level
//! equivariance is exact only for group elements that map the pixel grid onto itself.

pub use burn;

pub mod basis;
pub mod checkpoint;
pub mod device;
pub mod diagnostics;
pub mod group;
pub mod init;
pub mod kernels;
pub mod layers;
pub mod nets;
pub mod plain;
pub mod repr;
