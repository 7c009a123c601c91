use equiarm_sim::{Env, EnvConfig, TaskKind};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let task = TaskKind::from_name(&args[1]).unwrap();
    let seed: u64 = args[2].parse().unwrap();
    let mut cfg = EnvConfig::new(task);
    cfg.render = false;
    let mut env = Env::new(cfg).unwrap();
    let mut obs = env.reset(seed).unwrap();
    loop {
        let sc = env.scene().unwrap();
        let names = sc.seg_names.clone();
        let mut s = String::new();
        for (h, b) in sc.physics.bodies.iter() {
            let _ = h;
            let t = b.translation();
            let up = b.rotation() * rapier3d::prelude::Vector::Z;
            s += &format!("({:.3},{:.3},{:.3} up {:.2}) ", t.x, t.y, t.z, up.z);
        }
        for p in sc.physics.narrow_phase.contact_pairs() {
            if p.has_any_active_contact() {
                let a = sc.physics.colliders[p.collider1].parent().unwrap();
                let b = sc.physics.colliders[p.collider2].parent().unwrap();
                s += &format!("[{:?}-{:?}]", a.into_raw_parts().0, b.into_raw_parts().0);
            }
        }
        println!(
            "step {} tcp {:?} yaw {:.2} hold {} open {:.2} expert {:?}\n   {}",
            obs.step, obs.tcp, obs.yaw, obs.holding, obs.open_ratio, obs.expert_action, s
        );
        let _ = names;
        let bodies: Vec<_> = sc.physics.bodies.iter().map(|(h, _)| h).collect();
        if bodies.len() > 5 {
            let (a, b) = (bodies[4], bodies[5]);
            let mut md = 1.0f32;
            let mut mz = 0.0f32;
            for &x in sc.physics.bodies[a].colliders() {
                for &y in sc.physics.bodies[b].colliders() {
                    let (cx, cy) = (&sc.physics.colliders[x], &sc.physics.colliders[y]);
                    let d = rapier3d::parry::query::distance(
                        cx.position(),
                        cx.shape(),
                        cy.position(),
                        cy.shape(),
                    )
                    .unwrap()
                    .distance;
                    md = md.min(d);
                }
            }
            for &y in sc.physics.bodies[b].colliders() {
                let cy = &sc.physics.colliders[y];
                let aabb = cy.compute_aabb();
                mz = mz.max(aabb.maxs.z);
            }
            println!("   cube-bowl dist {md:.4} bowl aabb max z {mz:.4}");
        }
        let r = env.step(&obs.expert_action).unwrap();
        obs = r.observation;
        if r.done {
            println!("done {:?}", r.info);
            break;
        }
    }
}
