//! Test doubles for the board application: they implement the same narrow
//! hardware traits the boards implement, so the real application code runs here.

pub mod mock_flash;
pub mod onewire_emu;
pub mod qemu;

/// The unlock key the tests give their boards at commissioning (a fresh
/// board takes the factory code for commissioning only).
pub const TEST_UNLOCK_KEY: u16 = 0x7E57;

/// Give a fresh board its own unlock key [`TEST_UNLOCK_KEY`] as `tcomp
/// commission` does (factory code, register 67, command 15), and drive the
/// flash write to its end; the board ends locked. A board that has its
/// key already is left as it is.
pub fn commission<F: thermocomp::hal::flash::BackgroundErase>(app: &mut thermocomp::app::App<F>) {
    use thermocomp_protocol::holding::*;
    if app.server.holding.keys.unlock.is_some() {
        return; // commissioned already (a reboot of a commissioned board)
    }
    let unit = app.server.holding.unit;
    let mut reply = heapless::Vec::<u8, { thermocomp_protocol::rtu::MAX_FRAME }>::new();
    for (addr, v) in [
        (HR_UNLOCK, FACTORY_UNLOCK_CODE),
        (HR_NEW_UNLOCK_KEY, TEST_UNLOCK_KEY),
        (HR_COMMAND, CMD_SET_UNLOCK_KEY),
    ] {
        let [a, b] = addr.to_be_bytes();
        let [c, d] = v.to_be_bytes();
        let mut f = vec![unit, 6, a, b, c, d];
        f.extend_from_slice(&thermocomp_protocol::rtu::crc16(&f).to_le_bytes());
        app.request(&f, 0, &mut reply);
        assert_eq!(reply.get(1), Some(&6), "commissioning write {addr}={v:#x}: {reply:02x?}");
    }
    while app.poll_flash() {}
    assert_eq!(app.server.holding.keys.unlock, Some(TEST_UNLOCK_KEY));
}
