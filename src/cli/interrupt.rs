//! Ctrl-C, and the SIGTERM that schedulers (Slurm, Kubernetes), `timeout` and
//! `docker stop` send: the fit loop finishes its iteration, saves a checkpoint and the
//! command exits with 128 + the signal, as a shell reports a signalled process.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// Set by SIGINT or SIGTERM; the fit loop polls it after every iteration.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// Which of the two it was, for the exit status.
static SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(signal: libc::c_int) {
    SIGNAL.store(signal, Ordering::SeqCst);
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Installs the handlers and returns the flag they set.
pub fn install() -> &'static AtomicBool {
    // SAFETY: the handler only stores to atomics, which is async-signal-safe.
    unsafe {
        for signal in [libc::SIGINT, libc::SIGTERM] {
            libc::signal(signal, on_signal as *const () as libc::sighandler_t);
        }
    }
    &INTERRUPTED
}

/// Exits with 128 + the signal that interrupted (SIGINT if none was recorded).
pub fn exit() -> ! {
    let signal = match SIGNAL.load(Ordering::SeqCst) {
        0 => libc::SIGINT,
        s => s,
    };
    std::process::exit(128 + signal);
}
