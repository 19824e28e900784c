//! The holding band: which motor-angle errors the position loop leaves alone while the arm
//! holds, how hard it brakes a drive that slips, and whether the arm is *in position*.
//!
//! **Slip braking** ([`hold_brake`]): holding, `hold_damping` × the motor's speed comes off
//! its speed command, and at least [`SLIP_DAMPING`] × the part of the speed beyond
//! [`SLIP_SPEED`] — a slip after breakaway, braked hard so that it ends in or near the band,
//! while a drive creeping onto its target (slower than that) is damped only as configured.
//!
//! Holding, an error within `hold_deadband` gets no correction (a sticking drive would
//! otherwise hunt its last fraction of a milliradian). A drive that sticks and slips moves in
//! jumps: each breakaway releases the static friction's excess over the Coulomb level, and
//! the rotor slips a distance the drive sets, not the position loop. When that slip exceeds
//! twice the band the drive cannot come to rest inside it: it overshoots to the far side,
//! winds up, breaks away back, and hunts for ever (MuJoCo's sticking J6: ±0.78 mrad, a
//! breakaway every few seconds, docs/judge.md). The **hunting guard** ends that: a drive that
//! has crossed from one side of its band to the other [`HUNT_CROSSINGS`] times, is still,
//! stuck, and no nearer its target than [`HUNT_PROGRESS`] × where it rested before its last
//! crossing, is accepted where it stuck — its band widens to its error, at most
//! [`HUNT_BAND_MAX`] × the deadband, and only where that error moves the tool point by at
//! most [`HUNT_TOOL_M`] — until its target moves again. A drive whose error does not move the
//! tool point at all (a wrist roll about a tool on its axis: at most [`FREE_TOOL_M`]) is
//! accepted where it stuck as soon as it is still, without hunting first: waiting for it to
//! wind up, break away and slip buys the tool point nothing (MuJoCo's sticking J6 rested
//! 0.3–1.1 mrad off for the judge's whole 5 s wait in a third of its settles, docs/judge.md).
//! The guard looks at the tool *point*: an accepted wrist roll is an orientation error of up
//! to [`HUNT_BAND_MAX`] × the deadband (1 mrad in the shipped configurations); with the wrist
//! straight (J5 = 0) J4's axis passes through the tool point too. **In position**: holding,
//! every motor still and within its band (at least [`IN_POSITION_RAD`]) of its target;
//! `status.in_position`, what a client waits for before it measures.

/// The widest band the hunting guard accepts, as a multiple of `hold_deadband`: a drive
/// further off keeps being corrected.
pub const HUNT_BAND_MAX: f64 = 10.0;
/// The farthest the guard lets an accepted drive's error move the tool point, m: it accepts
/// a hunting drive only where that costs no accuracy (a wrist roll about the tool's own axis),
/// a shoulder hunting 0.1 mrad moves the tool 0.08 mm and keeps being corrected.
pub const HUNT_TOOL_M: f64 = 2e-5;
/// The farthest an error may move the tool point for the guard to accept the drive where it
/// rests without hunting first, m: 5 µm is 0.025× the resolvers' floor at the tool (0.2 mm);
/// only a joint whose axis passes (nearly) through the tool point qualifies — J2's 0.8 m lever
/// allows 6 µrad, inside any deadband.
pub const FREE_TOOL_M: f64 = 5e-6;
/// Crossings from one side of the band to the other before the guard may accept a drive:
/// one overshoot after a large slip is common on the way in (the stored torque is large),
/// hunting goes back and forth.
pub const HUNT_CROSSINGS: u32 = 2;
/// The guard accepts a drive only if it rests at least this fraction as far from its target
/// as it did on the other side before its last crossing: a drive whose error shrinks with
/// each slip is converging, not hunting.
pub const HUNT_PROGRESS: f64 = 0.5;
/// A motor slower than this (the low-passed resolver speed) for [`STILL_S`] counts as still,
/// rad/s: one resolver count a cycle is 3.8 mrad/s before the filter, a slipping drive
/// 0.02–0.1 rad/s.
pub const STILL_SPEED: f64 = 5e-3;
/// How long a motor stays below [`STILL_SPEED`] before it counts as still, s: a drive coming
/// to rest after a slip is below it for a few cycles before it stops.
pub const STILL_S: f64 = 0.02;
/// The in-position tolerance's floor, rad (≈ 2.6 resolver counts): with no deadband the
/// loop still rests on a count's jitter.
pub const IN_POSITION_RAD: f64 = 2e-5;
/// What the guard adds to an accepted error, rad (≈ 1.3 resolver counts): a count's jitter
/// does not restart the correction.
const ACCEPT_MARGIN_RAD: f64 = 1e-5;

/// The hold damping on a drive's speed beyond [`SLIP_SPEED`] (dimensionless; a configured
/// `hold_damping` above it is kept).
pub const SLIP_DAMPING: f64 = 4.0;
/// Holding, a motor faster than this is slipping after a breakaway, rad/s.
pub const SLIP_SPEED: f64 = 1e-2;

/// The speed the hold takes off a drive's speed command, rad/s, for the configured
/// `hold_damping` `base` and the motor's speed `speed` (rad/s): `base × speed`, and on the
/// part of the speed beyond [`SLIP_SPEED`] at least [`SLIP_DAMPING`] × it (none when `base`
/// is 0: damping off).
pub fn hold_brake(base: f64, speed: f64) -> f64 {
    let extra = if base > 0.0 {
        SLIP_DAMPING.max(base) - base
    } else {
        0.0
    };
    base * speed + extra * speed.signum() * (speed.abs() - SLIP_SPEED).max(0.0)
}

/// Per-joint holding band and in-position state (no allocation; updated every cycle).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct HoldBand {
    /// Errors within this are left alone, rad.
    band: [f64; 6],
    /// The sign of the last error outside the band (0: none since the target moved).
    side: [f64; 6],
    /// How often the error has changed sides outside the band since the target moved.
    crossings: [u32; 6],
    /// |error| where the drive last rested outside its band on this side and on the side
    /// before the last crossing, rad (0: none).
    rest: [[f64; 2]; 6],
    /// The target the band belongs to, rad.
    anchor: [f64; 6],
    /// How long each motor has been below [`STILL_SPEED`], s.
    slow_s: [f64; 6],
    /// Whether the last update was holding.
    holding: bool,
    in_position: bool,
}

impl HoldBand {
    /// One cycle of `dt` seconds: `holding` whether the loop holds, `deadband` the configured
    /// `hold_deadband` (rad), `target` the motor target and `q_motor` the resolvers (rad),
    /// `speed` the low-passed motor speeds (rad/s); `lever(j)` how far the tool point moves
    /// per radian of joint j, m/rad (asked only for a still drive outside its band and within
    /// the cap).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn update(
        &mut self,
        dt: f64,
        holding: bool,
        deadband: f64,
        target: &[f64; 6],
        q_motor: &[f64; 6],
        speed: &[f64; 6],
        mut lever: impl FnMut(usize) -> f64,
    ) {
        let mut in_position = holding;
        for j in 0..6 {
            let moved = (target[j] - self.anchor[j]).abs() > deadband.max(IN_POSITION_RAD);
            if !holding || !self.holding || moved {
                self.band[j] = deadband;
                self.side[j] = 0.0;
                self.crossings[j] = 0;
                self.rest[j] = [0.0; 2];
                self.anchor[j] = target[j];
            }
            let e = target[j] - q_motor[j];
            self.slow_s[j] = if speed[j].abs() < STILL_SPEED {
                self.slow_s[j] + dt
            } else {
                0.0
            };
            let still = self.slow_s[j] >= STILL_S - 1e-9;
            if holding && deadband > 0.0 && e.abs() > self.band[j] {
                let s = e.signum();
                if self.side[j] != 0.0 && s != self.side[j] {
                    self.crossings[j] += 1;
                    self.rest[j] = [0.0, self.rest[j][0]];
                }
                self.side[j] = s;
                if still {
                    self.rest[j][0] = e.abs();
                    let hunting = self.crossings[j] >= HUNT_CROSSINGS
                        && e.abs() >= HUNT_PROGRESS * self.rest[j][1];
                    if e.abs() <= HUNT_BAND_MAX * deadband {
                        let tool_m = lever(j) * e.abs();
                        if (hunting && tool_m <= HUNT_TOOL_M) || tool_m <= FREE_TOOL_M {
                            self.band[j] = e.abs() + ACCEPT_MARGIN_RAD;
                        }
                    }
                }
            }
            in_position &= still && e.abs() <= self.band[j].max(IN_POSITION_RAD);
        }
        self.holding = holding;
        self.in_position = in_position;
    }

    /// Joint `j`'s band, rad: errors within it get no correction while holding.
    pub(crate) fn band(&self, j: usize) -> f64 {
        self.band[j]
    }

    /// Holding, every motor still and within its band of its target.
    pub(crate) fn in_position(&self) -> bool {
        self.in_position
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DB: f64 = 1e-4;

    /// A wrist joint's lever with the tool point 20 mm off its axis, m/rad: an error of
    /// 0.25–1 mrad moves the tool point 5–20 µm (hunting is accepted, resting is not).
    const WRIST: f64 = 0.02;

    /// Two 10 ms cycles at errors `e` (target − motor, rad) and motor speeds `speed`, every
    /// joint's lever `lever` (m/rad).
    fn at_lever(band: &mut HoldBand, e: [f64; 6], speed: f64, lever: f64) {
        for _ in 0..2 {
            band.update(
                0.01,
                true,
                DB,
                &[0.0; 6],
                &e.map(|x| -x),
                &[speed; 6],
                |_| lever,
            );
        }
    }

    /// [`at_lever`] with the [`WRIST`] lever.
    fn at(band: &mut HoldBand, e: [f64; 6], speed: f64) {
        at_lever(band, e, speed, WRIST);
    }

    #[test]
    fn within_the_deadband_and_still_is_in_position_moving_or_outside_is_not() {
        let mut b = HoldBand::default();
        b.update(0.01, true, DB, &[0.0; 6], &[5e-5; 6], &[0.0; 6], |_| 0.0);
        assert!(!b.in_position(), "still for 10 ms only");
        at(&mut b, [5e-5; 6], 0.0);
        assert!(b.in_position());
        at(&mut b, [5e-5; 6], 0.02);
        assert!(!b.in_position(), "a slipping drive is not in position");
        let mut e = [5e-5; 6];
        e[1] = 3e-4;
        at(&mut b, e, 0.0);
        assert!(!b.in_position(), "J2 outside the band");
        // not holding: never in position
        b.update(0.01, false, DB, &[0.0; 6], &[0.0; 6], &[0.0; 6], |_| 0.0);
        assert!(!b.in_position());
    }

    #[test]
    fn a_drive_that_hunts_back_and_forth_is_accepted_where_it_sticks() {
        let mut b = HoldBand::default();
        let mut e = [0.0; 6];
        e[5] = 7.8e-4; // stuck on one side, winding up: corrected
        at(&mut b, e, 0.0);
        assert_eq!(b.band(5), DB);
        assert!(!b.in_position());
        e[5] = -7.7e-4; // slipped past the target and stuck: one crossing, still corrected
        at(&mut b, e, 0.05);
        at(&mut b, e, 0.0);
        assert_eq!(b.band(5), DB);
        e[5] = 7.6e-4; // and back, moving: not yet
        at(&mut b, e, 0.05);
        assert_eq!(b.band(5), DB);
        at(&mut b, e, 0.0); // stuck as far off as before: hunting, accepted where it is
        assert!((b.band(5) - (7.6e-4 + ACCEPT_MARGIN_RAD)).abs() < 1e-12);
        assert!(b.in_position());
        // a count of jitter does not restart the correction
        e[5] = 7.65e-4;
        at(&mut b, e, 0.0);
        assert!(b.in_position());
    }

    #[test]
    fn a_drive_converging_in_shrinking_slips_is_not_accepted_nor_one_beyond_the_cap() {
        let mut b = HoldBand::default();
        let mut e = [0.0; 6];
        for (err, accepted) in [
            (8e-4, false),
            (-5e-4, false),
            (2e-4, false),
            (-1.5e-4, true),
        ] {
            e[1] = err;
            // 0.1 m: 0.15 mrad moves the tool point 15 µm, 0.2 mrad 20 µm
            at_lever(&mut b, e, 0.0, 0.1);
            assert_eq!(b.band(1) > DB, accepted, "{err}");
        }
        // beyond the cap: corrected however it hunts, even on the tool's axis
        let mut b = HoldBand::default();
        for err in [2e-3, -2e-3, 2e-3, -2e-3] {
            e[1] = err;
            at_lever(&mut b, e, 0.0, 0.0);
            assert_eq!(b.band(1), DB);
        }
    }

    #[test]
    fn a_drive_whose_error_does_not_move_the_tool_point_is_accepted_where_it_rests_at_once() {
        let mut b = HoldBand::default();
        let mut e = [0.0; 6];
        e[5] = 5e-4; // J6 about a tool on its axis, slipping: not yet
        at_lever(&mut b, e, 0.05, 0.0);
        assert_eq!(b.band(5), DB);
        assert!(!b.in_position());
        at_lever(&mut b, e, 0.0, 0.0); // still: no crossing needed
        assert!((b.band(5) - (5e-4 + ACCEPT_MARGIN_RAD)).abs() < 1e-12);
        assert!(b.in_position());
        // a 1 mm tool offset (0.5 µm at the tool point) is still "on the axis"
        let mut b = HoldBand::default();
        at_lever(&mut b, e, 0.0, 1e-3);
        assert!(b.in_position());
        // the same error 20 mm off the axis moves the tool point 10 µm: corrected until it hunts
        let mut b = HoldBand::default();
        at(&mut b, e, 0.0);
        assert_eq!(b.band(5), DB);
        assert!(!b.in_position());
    }

    #[test]
    fn a_hunting_drive_whose_error_moves_the_tool_keeps_being_corrected() {
        let mut b = HoldBand::default();
        let mut q = [0.0; 6];
        for err in [3e-4, -3e-4, 3e-4, -3e-4] {
            q[1] = -err;
            for _ in 0..2 {
                // J2 0.8 m from the tool: 3e-4 rad moves it 0.24 mm
                b.update(0.01, true, DB, &[0.0; 6], &q, &[0.0; 6], |j| {
                    if j == 1 { 0.8 } else { 0.0 }
                });
            }
            assert_eq!(b.band(1), DB, "{err}");
        }
    }

    #[test]
    fn the_band_is_forgotten_when_the_target_moves() {
        let mut b = HoldBand::default();
        let mut e = [0.0; 6];
        for err in [3e-4, -3e-4, 3e-4] {
            e[1] = err;
            at(&mut b, e, 0.0);
        }
        assert!(b.band(1) > 3e-4, "accepted");
        // the target moves by more than the deadband: the band is the deadband again
        let mut target = [0.0; 6];
        target[1] = 5e-4;
        b.update(0.01, true, DB, &target, &[0.0; 6], &[0.0; 6], |_| WRIST);
        assert_eq!(b.band(1), DB);
        assert!(!b.in_position());
    }

    #[test]
    fn without_a_deadband_nothing_is_accepted_and_in_position_means_within_the_floor() {
        let mut b = HoldBand::default();
        for e in [3e-4, -3e-4, 3e-4] {
            b.update(0.01, true, 0.0, &[0.0; 6], &[e; 6], &[0.0; 6], |_| 0.0);
            assert_eq!(b.band(0), 0.0);
            assert!(!b.in_position());
        }
        for _ in 0..2 {
            b.update(0.01, true, 0.0, &[0.0; 6], &[1e-5; 6], &[0.0; 6], |_| 0.0);
        }
        assert!(b.in_position());
    }

    #[test]
    fn the_hold_brakes_a_slip_harder_than_a_creep_and_not_at_all_when_damping_is_off() {
        // below the slip speed: the configured damping alone (a creeping drive as before)
        for v in [0.0, 2e-3, -9e-3] {
            assert_eq!(hold_brake(1.0, v), v);
        }
        // beyond it: SLIP_DAMPING on the excess, continuous at the threshold, odd in the speed
        let v = 0.05;
        let want = v + (SLIP_DAMPING - 1.0) * (v - SLIP_SPEED);
        assert!((hold_brake(1.0, v) - want).abs() < 1e-15);
        assert!((hold_brake(1.0, -v) + want).abs() < 1e-15);
        assert!((hold_brake(1.0, SLIP_SPEED + 1e-12) - SLIP_SPEED).abs() < 1e-11);
        // a configured damping above SLIP_DAMPING is kept; 0 turns the hold's damping off
        assert_eq!(hold_brake(6.0, v), 6.0 * v);
        assert_eq!(hold_brake(0.0, v), 0.0);
    }
}
