//! The `pa10d` control daemon's library side: configuration (and, as the `[daemon]` issue
//! proceeds, the control loop, motion, the client API and the safety supervisor).

pub mod api;
pub mod config;
pub mod control;
pub mod link;
pub mod motion;
pub mod realtime;
pub mod runtime;
