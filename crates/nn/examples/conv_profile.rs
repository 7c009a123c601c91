//! Where the time of a training step goes: times burn-flex's conv2d forward, input gradient
//! (conv_transpose2d), weight gradient, and max-pool backward for the layer shapes of the Equi
//! actor, at batch 128. `cargo run -p equiarm_nn --release --example conv_profile -- [paper|reduced]`

use clap::{Parser, ValueEnum};
use equiarm_nn::burn::tensor::module::{conv_transpose2d, conv2d, conv2d_weight_backward};
use equiarm_nn::burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use std::time::Instant;

fn t<const D: usize>(f: impl Fn() -> Tensor<D>) -> f64 {
    let _ = f().into_data();
    let mut v: Vec<f64> = (0..3)
        .map(|_| {
            let s = Instant::now();
            let _ = f().into_data();
            s.elapsed().as_secs_f64()
        })
        .collect();
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[1]
}

fn rand<const D: usize>(shape: [usize; D], dev: &Device) -> Tensor<D> {
    let n = shape.iter().product();
    Tensor::from_data(TensorData::new(Init::new(0).normal("p", n, 1.0), shape), dev)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Config {
    /// Hidden 64, 128 px.
    Paper,
    /// Hidden 16, 64 px.
    Reduced,
}

/// Times the convolutions of a training step of the Equi actor at batch 128.
#[derive(Parser, Debug)]
#[command(name = "conv_profile")]
struct Args {
    /// The network configuration whose layer shapes are timed.
    #[arg(value_enum, default_value_t = Config::Reduced)]
    config: Config,
}

fn main() {
    let paper = Args::parse().config == Config::Paper;
    let (n, s0) = if paper { (64, 128) } else { (16, 64) };
    let b = 128;
    let dev = Device::flex();
    // (cin, cout, size, pad) per layer of the encoder
    let mut layers = vec![(5, n, s0, 1)];
    let ch = [n, 2 * n, 4 * n, 8 * n, 16 * n, 8 * n, 8 * n];
    let mut s = s0;
    for i in 1..7 {
        if i <= 4 {
            s /= if i <= (if paper { 4 } else { 3 }) { 2 } else { 1 };
        }
        if i == 6 {
            s = 3;
        }
        layers.push((ch[i - 1], ch[i], s, if i >= 5 { 0 } else { 1 }));
    }
    println!("{:>5} {:>5} {:>5} {:>4} {:>9} {:>9} {:>9}", "cin", "cout", "size", "pad", "fwd s", "dx s", "dw s");
    let (mut tf, mut tx, mut tw) = (0.0, 0.0, 0.0);
    for (cin, cout, size, pad) in layers {
        let x = rand([b, cin, size, size], &dev);
        let w = rand([cout, cin, 3, 3], &dev);
        let so = size + 2 * pad - 2;
        let g = rand([b, cout, so, so], &dev);
        let opt = ConvOptions::new([1, 1], [pad, pad], [1, 1], 1);
        let f = t(|| conv2d(x.clone(), w.clone(), None, opt.clone()));
        let dx = t(|| {
            conv_transpose2d(
                g.clone(),
                w.clone(),
                None,
                ConvTransposeOptions::new([1, 1], [pad, pad], [0, 0], [1, 1], 1),
            )
        });
        let dw = t(|| conv2d_weight_backward(x.clone(), w.clone(), g.clone(), opt.clone()));
        println!("{cin:>5} {cout:>5} {size:>5} {pad:>4} {f:>9.4} {dx:>9.4} {dw:>9.4}");
        tf += f;
        tx += dx;
        tw += dw;
    }
    println!("total fwd {tf:.3} s, input grad {tx:.3} s, weight grad {tw:.3} s");
}
