//! Real-time options of the control thread: SCHED_FIFO for that thread only, and mlockall for
//! the process. Both are optional and degrade to a warning when not permitted (an
//! unprivileged user, a container without CAP_SYS_NICE / CAP_IPC_LOCK or the matching
//! `LimitRTPRIO` / `LimitMEMLOCK`).

/// Puts the calling thread under SCHED_FIFO at `priority` (1…99). Err says why not.
#[cfg(target_os = "linux")]
pub fn set_fifo(priority: u8) -> Result<(), String> {
    let param = libc::sched_param {
        sched_priority: priority as libc::c_int,
    };
    // SAFETY: pthread_self() is the calling thread, and `param` is a valid, initialised
    // sched_param that outlives the call.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::from_raw_os_error(rc).to_string())
    }
}

/// Locks all current and future memory of the process. Err says why not.
#[cfg(target_os = "linux")]
pub fn lock_memory() -> Result<(), String> {
    // SAFETY: mlockall takes flags only and touches no memory of ours.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error().to_string())
    }
}

/// Not available off Linux.
#[cfg(not(target_os = "linux"))]
pub fn set_fifo(_priority: u8) -> Result<(), String> {
    Err("SCHED_FIFO needs Linux".into())
}

/// Not available off Linux.
#[cfg(not(target_os = "linux"))]
pub fn lock_memory() -> Result<(), String> {
    Err("mlockall needs Linux".into())
}

#[cfg(test)]
mod tests {
    #[test]
    fn refusals_are_reported_not_fatal() {
        // Whatever this machine permits, the calls return and say why when they fail.
        let r = std::thread::spawn(|| super::set_fifo(10)).join().unwrap();
        if let Err(e) = r {
            assert!(!e.is_empty());
        }
    }
}
