//! Degraded mode on the register map (issue 15): input registers 150–157
//! and the result codes of the image format v2 refusals.
use thermocomp::modbus::registers::*;
use thermocomp_core::compensator::ACTIVE_NONE;
use thermocomp_core::ImageError;
use thermocomp_protocol::holding::result;
use thermocomp_protocol::registers::*;

#[test]
fn active_model_registers_name_the_model_per_direction() {
    let mut s = Snapshot {
        n_directions: 3,
        ..Snapshot::default()
    };
    s.active = [1, 2, 0, ACTIVE_NONE, ACTIVE_NONE, ACTIVE_NONE];
    let r = |a| s.input_register(a).unwrap();
    assert_eq!(
        [r(150), r(151), r(152), r(153), r(154), r(155)],
        [1, 2, 0, 0xFFFF, 0xFFFF, 0xFFFF]
    );
    assert_eq!(r(IR_DEGRADED_DIRECTIONS), 0b011);
    assert_eq!(r(IR_HELD_DIRECTIONS), 0);
    s.active = [0, ACTIVE_NONE, 3, ACTIVE_NONE, ACTIVE_NONE, ACTIVE_NONE];
    let r = |a| s.input_register(a).unwrap();
    assert_eq!(r(IR_DEGRADED_DIRECTIONS), 0b100);
    assert_eq!(r(IR_HELD_DIRECTIONS), 0b010, "only the model's directions");
    assert_eq!((r(158), r(159)), (0, 0));
    // 160–179 are the board-safety block; the map ends at IR_LAST after it.
    // The volumetric block follows it (180: x, not available without a section).
    assert_eq!(s.input_register(IR_SAFETY_LAST + 1), Some(NOT_AVAILABLE));
    assert_eq!(s.input_register(IR_LAST + 1), None);
    // Before any model: no model serves any direction.
    let d = Snapshot::default();
    assert_eq!(d.input_register(IR_ACTIVE_MODEL), Some(0xFFFF));
}

#[test]
fn image_v2_refusals_have_their_own_result_codes() {
    let codes = [
        (
            ImageError::UnknownSection { kind: 9 },
            30,
            "UNKNOWN_SECTION",
        ),
        (ImageError::SectionLength { kind: 1 }, 31, "SECTION_LENGTH"),
        (
            ImageError::DuplicateSection { kind: 1 },
            32,
            "DUPLICATE_SECTION",
        ),
        (
            ImageError::FallbackUsesExcluded {
                fallback: 0,
                sensor: 2,
            },
            33,
            "FALLBACK_USES_EXCLUDED",
        ),
    ];
    for (e, code, name) in codes {
        assert_eq!(result::of_image_error(&e), code, "{e}");
        assert_eq!(result::name(code), name);
    }
}
