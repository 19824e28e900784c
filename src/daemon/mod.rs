//! The `pa10d` control daemon's library side.
//!
//! Sans IO, plain functions and state machines on plain data: [`link`] (the host side of the
//! servo protocol session), [`control`] (one control cycle), [`plan`] (moves and trajectories, off-cycle),
//! [`core`] (link + cycle + client commands + status, one state machine), [`stats`] and
//! [`wire`] (the client protocol's request, reply and status types, and their JSON Schema).
//! At the edges: [`runtime`] (the real-time control thread on a real bus), [`api`] (the
//! client socket), [`config`] and [`realtime`] (scheduling and memory locking).

pub mod api;
pub mod config;
pub mod control;
pub mod core;
pub mod link;
pub mod live;
pub mod plan;
pub mod realtime;
pub mod runtime;
pub mod timing;
pub mod vocab;
pub mod wire;
