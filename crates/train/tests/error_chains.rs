//! One error convention (docs/conventions.md, "Errors"): a cause is shown in the message or chained as
//! `source()`, never both, so a user reading the chain (`{:#}`, as `equiarm` prints errors) sees each
//! cause once. For one value of every error type that wraps another error, this walks the chain and
//! fails if a message contains the text of its source.

use std::error::Error;
use std::io;
use std::path::{Path, PathBuf};

fn io_error() -> io::Error {
    io::Error::from(io::ErrorKind::NotFound)
}

/// Every message in `e`'s chain, and the check that none repeats its source's.
fn chain(e: &(dyn Error + 'static)) -> Vec<String> {
    let mut out = vec![e.to_string()];
    let mut cur = e;
    while let Some(src) = cur.source() {
        let (outer, inner) = (cur.to_string(), src.to_string());
        assert!(!outer.contains(&inner), "`{outer}` repeats its source `{inner}`");
        out.push(inner);
        cur = src;
    }
    out
}

#[test]
fn no_message_repeats_its_source() {
    use equiarm_bag::BagError;
    use equiarm_sac::frame::FrameError;
    let frame = || FrameError::BadSize { size: 0, max: 512 };
    let sim = || equiarm_sim::SimError::Read { file: "gripper.urdf".into(), cause: io_error() };
    let path = PathBuf::from("some/file");
    let errors: Vec<Box<dyn Error>> = vec![
        Box::new(equiarm_types::files::at(&path)(io_error())),
        Box::new(BagError::from(equiarm_types::files::at(&path)(io_error()))),
        Box::new(equiarm_bag::DecodeError::Cdr {
            topic: "/env0/observation".into(),
            cause: equiarm_msgs::cdr::decode::<equiarm_msgs::msg::Observation>(&[0]).unwrap_err(),
        }),
        Box::new(sim()),
        Box::new(equiarm_train::plot::PlotError::from(equiarm_types::files::at(&path)(io_error()))),
        Box::new(equiarm_train::stepper::StepError::Sim { what: "stepping the env".into(), cause: sim() }),
        Box::new(equiarm_train::metrics::MetricsError::from(equiarm_types::files::at(&path)(io_error()))),
        Box::new(equiarm_sac::optim::OptimError::from(equiarm_types::files::at(&path)(io_error()))),
        Box::new(equiarm_sac::learner::JsonFileError::from(equiarm_types::files::at(&path)(io_error()))),
        Box::new(equiarm_sac::augment::AugmentError::Frame { index: 1, cause: frame() }),
        Box::new(equiarm_sac::replay::ReplayError::Io { path: path.clone(), op: "opening", cause: io_error() }),
        Box::new(equiarm_sac::agent::AgentError::Net {
            model: "equi",
            cause: equiarm_nn::nets::NetError::Config("hidden 12".into()),
        }),
        Box::new(equiarm_nn::layers::LayerError::Basis {
            path: "enc.0".into(),
            cause: equiarm_nn::basis::BasisError::KernelSize(5),
        }),
        Box::new(equiarm_train::TrainError::from(sim())),
        Box::new(equiarm_train::TrainError::from(frame())),
        Box::new(equiarm_train::policy::AnswerError::from(equiarm_sac::learner::LearnerError::from(
            equiarm_sac::augment::AugmentError::Frame { index: 0, cause: frame() },
        ))),
    ];
    for e in &errors {
        let messages = chain(e.as_ref());
        assert!(!messages[0].is_empty());
    }
}

/// The case users met: `equiarm bag info /nonexistent` printed the OS error twice.
#[test]
fn a_missing_bag_names_its_cause_once() {
    let Err(e) = equiarm_bag::Reader::open(Path::new("/nonexistent/bag")) else { panic!("opened a missing bag") };
    let shown = format!("{:#}", anyhow::Error::from(e));
    assert_eq!(shown.matches("No such file or directory").count(), 1, "{shown}");
}
