//! The `pa10d` control daemon's library side.
//!
//! Sans IO, plain functions and state machines on plain data: [`vocab`] (the shared leaf:
//! joint state, setpoint, limits), [`link`] (the host side of the servo protocol session),
//! [`control`] (one control cycle), [`plan`] (moves, trajectories and Cartesian paths,
//! off-cycle), [`core`] (link + cycle + client commands + status, one state machine),
//! [`timing`] (the loop's timing histograms) and [`wire`] (the client protocol's request,
//! reply and status types, and their JSON Schema).
//! At the edges: [`runtime`] (the real-time control thread on a real bus), [`api`] (the
//! client socket), `live` (the Foxglove WebSocket view; feature `live`), [`config`] and
//! [`realtime`] (scheduling and memory locking).

pub mod api;
pub mod config;
pub mod control;
pub mod core;
pub mod link;
#[cfg(feature = "live")]
pub mod live;
pub mod plan;
pub mod realtime;
pub mod runtime;
pub mod timing;
pub mod vocab;
pub mod wire;
