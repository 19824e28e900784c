//! The loop's modes as one table: the code every cycle record persists, the name status,
//! events and readers show. The recording's schema, the daemon's status and events, the CSV
//! export and the still-phase reader all use this table and no other.

/// What the control loop is doing, as persisted in [`super::CycleSample::activity`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Mode {
    /// Holding the setpoint.
    Holding = 0,
    /// Running a planned move.
    Moving = 1,
    /// Following a timed trajectory.
    Following = 2,
    /// Following a servo, jog or twist stream.
    Streaming = 3,
    /// Decelerating to rest.
    Stopping = 4,
    /// Stopped by a fault; commands zero until reset.
    Faulted = 5,
}

impl Mode {
    /// Every mode, in code order.
    pub const ALL: [Mode; 6] = [
        Mode::Holding,
        Mode::Moving,
        Mode::Following,
        Mode::Streaming,
        Mode::Stopping,
        Mode::Faulted,
    ];

    /// The persisted code.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The mode of a persisted code; `None` for a code no mode has.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code)).copied()
    }

    /// The name status and events use (`fault` for [`Mode::Faulted`]).
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Holding => "holding",
            Mode::Moving => "moving",
            Mode::Following => "following",
            Mode::Streaming => "streaming",
            Mode::Stopping => "stopping",
            Mode::Faulted => "fault",
        }
    }
}

/// The schema's description of the `activity` field, from the table: `0 holding, 1 moving, …`.
pub fn describe_codes() -> String {
    Mode::ALL
        .iter()
        .map(|m| format!("{} {}", m.code(), m.name()))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_the_schema_says_what_the_table_says() {
        for m in Mode::ALL {
            assert_eq!(Mode::from_code(m.code()), Some(m));
        }
        assert_eq!(Mode::from_code(6), None);
        let schema: serde_json::Value =
            serde_json::from_str(super::super::CYCLE_SCHEMA).expect("schema parses");
        assert_eq!(
            schema["properties"]["activity"]["description"],
            describe_codes()
        );
    }
}
