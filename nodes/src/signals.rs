//! SIGINT (Ctrl-C) and SIGTERM: a future the nodes select on, and a flag for blocking loops.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context as _;

/// Resolves when the process gets SIGINT (Ctrl-C) or SIGTERM; nodes select on it to shut down cleanly.
pub async fn shutdown_signal() -> anyhow::Result<&'static str> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
        let mut int = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
        tokio::select! {
            _ = term.recv() => Ok("SIGTERM"),
            _ = int.recv() => Ok("SIGINT"),
        }
    }
    #[cfg(not(unix))]
    {
        tokio::signal::ctrl_c().await.context("installing the Ctrl-C handler")?;
        Ok("Ctrl-C")
    }
}

/// A flag that turns true on SIGINT or SIGTERM (a helper thread waits for the signal).
pub fn stop_flag() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
            Ok(rt) => rt,
            Err(e) => {
                log::warn!("no signal handler: {e}");
                return;
            }
        };
        rt.block_on(async {
            // The first poll installs the handlers; only then is the flag armed.
            let signal = shutdown_signal();
            tokio::pin!(signal);
            if let std::task::Poll::Ready(r) = futures::poll!(&mut signal) {
                log::warn!("no SIGINT/SIGTERM handler: {r:?}");
                return;
            }
            let _ = tx.send(());
            if let Ok(sig) = signal.await {
                log::info!("{sig}: stopping after the current step and writing a checkpoint");
                flag.store(true, Ordering::Relaxed);
            }
        });
    });
    let _ = rx.recv_timeout(std::time::Duration::from_secs(1));
    stop
}
