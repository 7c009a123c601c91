//! Measure the equivariance error of a saved network per group element (until the `equiarm`
//! binary wires `equiarm nn check-equivariance CKPT`).
//!
//! `cargo run -p equiarm_nn --example check_equivariance -- CKPT|--fresh [equi-actor|equi-critic|rot-equi]
//!  [--hidden 64] [--size 128] [--channels 5] [--batch 2] [--seed 0]`
//! (`--fresh`: no file, the seeded initial weights.)

use equiarm_nn::burn::tensor::Device;
use equiarm_nn::diagnostics::{check_checkpoint, NetKind};
use equiarm_nn::nets::NetConfig;

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: check_equivariance CKPT|--fresh [equi-actor|equi-critic|rot-equi] [--hidden N] [--size N] [--channels N] [--batch N] [--seed N]";
    let Some(path) = argv.first() else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    let mut kind = NetKind::EquiActor;
    let mut cfg = NetConfig::paper();
    let (mut batch, mut seed) = (2usize, 0u64);
    let mut i = 1;
    while i < argv.len() {
        let num = || argv.get(i + 1).and_then(|v| v.parse::<usize>().ok()).unwrap_or_else(|| {
            eprintln!("{}: expected a number\n{usage}", argv[i]);
            std::process::exit(2)
        });
        match argv[i].as_str() {
            "--hidden" => { cfg.hidden = num(); i += 1; }
            "--size" => { cfg.input_size = num(); i += 1; }
            "--channels" => { cfg.in_channels = num(); i += 1; }
            "--batch" => { batch = num(); i += 1; }
            "--seed" => { seed = num() as u64; i += 1; }
            other => match other.parse() {
                Ok(k) => kind = k,
                Err(e) => { eprintln!("{e}\n{usage}"); std::process::exit(2); }
            },
        }
        i += 1;
    }
    let file = (path != "--fresh").then(|| std::path::Path::new(path));
    match check_checkpoint(kind, &cfg, file, batch, seed, &Device::flex()) {
        Ok(errs) => {
            println!("element (flip, rot)   relative error");
            for e in errs {
                println!("({}, {})                {:.3e}", e.element.flip, e.element.rot, e.relative_error);
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
