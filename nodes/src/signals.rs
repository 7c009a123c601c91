//! SIGINT (Ctrl-C) and SIGTERM: one listener per process, a future the nodes select on, and a flag for
//! blocking loops.
//!
//! Each node calls [`install`] first thing, before it joins the DDS domain. From then on a signal is
//! never lost: one that arrives while the node starts up is remembered, and the node's main loop sees
//! it at its first turn and shuts down cleanly (without the listener, the default action would end the
//! process before it logged anything or closed its files). A second signal ends the process at once
//! (exit status 130), for a node that is stuck.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context as _, anyhow};
use tokio::sync::watch;

/// The name of the first signal received, once there is one.
type Received = watch::Receiver<Option<&'static str>>;

static LISTENER: Mutex<Option<Received>> = Mutex::new(None);

/// Installs the process's SIGINT and SIGTERM handlers (once; later calls return the same listener).
pub fn install() -> anyhow::Result<Received> {
    let mut slot = LISTENER.lock().map_err(|_| anyhow!("the signal listener's lock is poisoned"))?;
    if let Some(rx) = slot.as_ref() {
        return Ok(rx.clone());
    }
    let (tx, rx) = watch::channel(None);
    let (armed_tx, armed_rx) = std::sync::mpsc::channel::<anyhow::Result<()>>();
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            let rt = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
                Ok(rt) => rt,
                Err(e) => {
                    let _ = armed_tx.send(Err(anyhow!(e).context("starting the signal listener's runtime")));
                    return;
                }
            };
            rt.block_on(listen(tx, armed_tx));
        })
        .context("starting the signal listener's thread")?;
    armed_rx.recv_timeout(Duration::from_secs(10)).context("the signal listener did not start within 10 s")??;
    *slot = Some(rx.clone());
    Ok(rx)
}

#[cfg(unix)]
async fn listen(tx: watch::Sender<Option<&'static str>>, armed: std::sync::mpsc::Sender<anyhow::Result<()>>) {
    use tokio::signal::unix::{SignalKind, signal};
    let handlers = signal(SignalKind::terminate())
        .context("installing the SIGTERM handler")
        .and_then(|term| Ok((term, signal(SignalKind::interrupt()).context("installing the SIGINT handler")?)));
    let (mut term, mut int) = match handlers {
        Ok(h) => h,
        Err(e) => {
            let _ = armed.send(Err(e));
            return;
        }
    };
    let _ = armed.send(Ok(()));
    loop {
        let name = tokio::select! {
            _ = term.recv() => "SIGTERM",
            _ = int.recv() => "SIGINT",
        };
        if let Some(first) = *tx.borrow() {
            eprintln!("{name} after {first}: exiting now");
            std::process::exit(130);
        }
        tx.send_replace(Some(name));
    }
}

#[cfg(not(unix))]
async fn listen(tx: watch::Sender<Option<&'static str>>, armed: std::sync::mpsc::Sender<anyhow::Result<()>>) {
    let _ = armed.send(Ok(()));
    loop {
        if let Err(e) = tokio::signal::ctrl_c().await {
            log::warn!("no Ctrl-C handler: {e}");
            return;
        }
        if tx.borrow().is_some() {
            eprintln!("Ctrl-C again: exiting now");
            std::process::exit(130);
        }
        tx.send_replace(Some("Ctrl-C"));
    }
}

/// Resolves when the process gets SIGINT (Ctrl-C) or SIGTERM, at once if it already has (since
/// [`install`]); nodes select on it to shut down cleanly.
pub async fn shutdown_signal() -> anyhow::Result<&'static str> {
    let mut rx = install()?;
    let got = rx.wait_for(Option::is_some).await.context("the signal listener stopped")?;
    Ok(got.unwrap_or("a signal"))
}

/// What a training run does on its first SIGINT or SIGTERM (the [`stop_flag`] message).
pub const CHECKPOINT_AND_STOP: &str = "stopping after the current step and writing a checkpoint";

/// A flag that turns true on SIGINT or SIGTERM (a helper thread waits for the signal, then logs
/// `what`, what the process does about it). Without a listener (which [`install`] reports) it stays
/// false and the default actions apply.
pub fn stop_flag(what: &'static str) -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let mut rx = match install() {
        Ok(rx) => rx,
        Err(e) => {
            log::warn!("no SIGINT/SIGTERM handler: {e:#}");
            return stop;
        }
    };
    let flag = stop.clone();
    let waiter = std::thread::Builder::new().name("stop-flag".into()).spawn(move || {
        if let Ok(Some(sig)) = futures::executor::block_on(rx.wait_for(Option::is_some)).map(|s| *s) {
            log::info!("{sig}: {what}");
            flag.store(true, Ordering::Relaxed);
        }
    });
    if let Err(e) = waiter {
        log::warn!("no thread to watch for SIGINT/SIGTERM: {e}");
    }
    stop
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A signal that comes before anyone waits for it (a node still starting up) is remembered: the
    /// process lives on, and the wait that starts later ends at once with the signal's name.
    #[test]
    fn a_signal_before_the_wait_is_not_lost() {
        let stop = stop_flag(CHECKPOINT_AND_STOP);
        let rx = install().unwrap();
        assert!(rx.borrow().is_none());
        let pid = std::process::id().to_string();
        let status = std::process::Command::new("kill").args(["-INT", &pid]).status().unwrap();
        assert!(status.success());
        let t0 = std::time::Instant::now();
        while rx.borrow().is_none() {
            assert!(t0.elapsed() < Duration::from_secs(10), "SIGINT not seen within 10 s");
            std::thread::sleep(Duration::from_millis(10));
        }
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let got = rt.block_on(async { tokio::time::timeout(Duration::from_secs(5), shutdown_signal()).await });
        assert_eq!(got.unwrap().unwrap(), "SIGINT");
        while !stop.load(Ordering::Relaxed) {
            assert!(t0.elapsed() < Duration::from_secs(10), "the stop flag did not turn true");
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}
