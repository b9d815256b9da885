//! thermocomp-core: the compensator's math, shared bit-exact by the firmware and
//! the desktop tools. No hardware, no heap, no floats on the evaluation path.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
