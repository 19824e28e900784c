//! Calibration, the noise estimator and discovery judged on data from the independent
//! generator (`tests/indep`), which shares no code with `src/`.

#[path = "indep/mod.rs"]
mod indep;

use indep::{Hidden, Spec, families, generate, write};

/// Writes sets for manual study: `PA10_INDEP_DIR=/tmp/x cargo test --release dump_sets -- --ignored`.
#[test]
#[ignore]
fn dump_sets() {
    let dir = std::path::PathBuf::from(std::env::var("PA10_INDEP_DIR").unwrap());
    for fam in families() {
        for (tag, hidden) in [
            ("clean", Hidden::None),
            ("j4", Hidden::SpringJ4(4000.0)),
            ("quad", Hidden::QuadraticJ2(-4e-4)),
        ] {
            let set = generate(&Spec {
                hidden,
                ..Spec::paper(1, fam)
            });
            write(&set, &dir.join(format!("{}-{tag}", fam.name)));
            println!("{} {tag}: floor {:.3} mm", fam.name, set.val_floor_mm);
        }
    }
}
