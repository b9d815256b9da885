//! A/B model slots on a NOR flash double that loses power at every possible
//! operation: after the reboot the board always has the old model or the new
//! one, never a broken one and never none.
use host_tests::mock_flash::{MockFlash, ERASE_SIZE};
use thermocomp::model_store::{ModelStore, StoreError};
use thermocomp_core::float::demo_model;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;

const SLOT: u32 = (8 * ERASE_SIZE) as u32;

fn image(version: u32) -> (Model, Vec<u8>) {
    let mut fm = demo_model(u64::from(version));
    fm.model_version = version;
    let (mut m, _) = fm.quantize().unwrap();
    let mut b = vec![0u8; m.encoded_len()];
    m.encode(&mut b).unwrap();
    (Model::parse(&b).unwrap(), b)
}

#[test]
fn commit_then_reboot_loads_the_newest_model() {
    let mut buf = [0u8; MAX_IMAGE_BYTES];
    let mut store = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
    assert!(store.load(&mut buf).is_none(), "blank flash has no model");
    for v in 1..=5 {
        let (m, b) = image(v);
        store.commit(&b).unwrap();
        let flash = std::mem::replace(store.flash(), MockFlash::new(0));
        store = ModelStore::new(flash, SLOT);
        assert_eq!(store.load(&mut buf), Some(m), "after commit {v}");
    }
    assert_eq!(store.commit(&[]), Err(StoreError::TooLarge));
}

#[test]
fn power_loss_at_every_operation_leaves_old_or_new_never_broken() {
    let (old, old_bytes) = image(1);
    let (new, new_bytes) = image(2);
    let mut buf = [0u8; MAX_IMAGE_BYTES];
    // Count the operations of one clean commit.
    let mut probe = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
    probe.commit(&old_bytes).unwrap();
    let before = probe.flash().operations;
    probe.commit(&new_bytes).unwrap();
    let per_commit = probe.flash().operations - before;
    assert!(per_commit > 100, "{per_commit} operations");
    let mut saw_old = 0;
    let mut saw_new = 0;
    for cut in 0..=per_commit {
        // Start from flash holding the old model in slot A and a stale copy in B.
        let mut store = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
        store.commit(&old_bytes).unwrap();
        store.commit(&old_bytes).unwrap();
        store.commit(&old_bytes).unwrap();
        store.flash().budget = Some(cut);
        let result = store.commit(&new_bytes);
        assert_eq!(result.is_ok(), cut >= per_commit, "cut at {cut}");
        // Reboot.
        let mut flash = std::mem::replace(store.flash(), MockFlash::new(0));
        flash.power_on();
        let mut rebooted = ModelStore::new(flash, SLOT);
        match rebooted.load(&mut buf) {
            Some(m) if m == old => saw_old += 1,
            Some(m) if m == new => saw_new += 1,
            other => panic!("cut at {cut}: {other:?}"),
        }
    }
    assert!(saw_old > 0 && saw_new > 0, "old {saw_old}, new {saw_new}");
}

#[test]
fn a_corrupted_slot_falls_back_to_the_other() {
    let (old, old_bytes) = image(1);
    let (_, new_bytes) = image(2);
    let mut buf = [0u8; MAX_IMAGE_BYTES];
    let mut store = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
    store.commit(&old_bytes).unwrap();
    store.commit(&new_bytes).unwrap();
    // Flip a bit inside the newer slot's image (slot B): CRC fails, A serves.
    store.flash().bytes[SLOT as usize + 100] ^= 0x10;
    let flash = std::mem::replace(store.flash(), MockFlash::new(0));
    let mut rebooted = ModelStore::new(flash, SLOT);
    assert_eq!(rebooted.load(&mut buf), Some(old));
}
