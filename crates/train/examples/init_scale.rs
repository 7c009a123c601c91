//! Diagnostic: activation scale per layer of freshly initialised actors on rendered frames.
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::layers::{max_pool2, relu};
use equiarm_nn::nets::{Actor, EquiActor, NetConfig};
use equiarm_sac::config::TrainConfig;
use equiarm_types::OBS_PLANES;

fn stats(t: &Tensor<4>) -> (f32, f32) {
    let v = t.clone().into_data().try_into_vec::<f32>().unwrap();
    let n = v.len() as f32;
    let m = v.iter().sum::<f32>() / n;
    let rms = (v.iter().map(|x| x * x).sum::<f32>() / n).sqrt();
    (m, rms)
}

fn main() {
    let (frame, input, hidden) = (76usize, 64usize, 16usize);
    let mut cfg = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    cfg.image_size = frame;
    let mut env = equiarm_sim::Env::new(equiarm_train::env::env_config(&cfg).unwrap()).unwrap();
    let mut frames = Vec::new();
    for s in 0..8 {
        let o = env.reset(s).unwrap();
        frames.push(equiarm_train::env::frame_of(&o).unwrap());
    }
    let refs: Vec<&equiarm_sac::frame::StoredFrame> = frames.iter().map(|f| &**f).collect();
    let c = equiarm_sac::augment::center_offset(frame, input);
    let x = equiarm_sac::augment::network_input(&refs, &[(c, c); 8], input).unwrap();
    let dev = Device::flex();
    let mut t = Tensor::<4>::from_data(TensorData::new(x, [8, OBS_PLANES, input, input]), &dev);
    let net = NetConfig::new(hidden, input, OBS_PLANES);
    let actor = EquiActor::new(&net, &Init::new(0), &dev).unwrap();
    println!("input mean/rms {:?}", stats(&t));
    let pools = [true, true, true, false, false, true, false];
    for (i, conv) in actor.enc.convs.iter().enumerate() {
        t = conv.forward(t);
        println!("conv {i} pre-relu mean/rms {:?}", stats(&t));
        t = relu(t);
        if pools[i] {
            t = max_pool2(t);
        }
    }
    let y = actor.head.forward(t);
    println!("head mean/rms {:?}", stats(&y));
    let x2 = equiarm_sac::augment::network_input(&refs, &[(c, c); 8], input).unwrap();
    let (m, ls) = actor.forward(Tensor::from_data(TensorData::new(x2, [8, OBS_PLANES, input, input]), &dev));
    println!("mean {:?}", m.into_data().try_into_vec::<f32>().unwrap()[..10].to_vec());
    println!("log_std {:?}", ls.into_data().try_into_vec::<f32>().unwrap()[..5].to_vec());
}
