//! Monotonic time. The application never reads a timer register; it asks the
//! board for milliseconds since boot (embassy-time on both boards, a virtual
//! clock in host tests).

/// Milliseconds since boot, monotonic, never wrapping in the product's life
/// (u64 ms is 584 million years).
pub trait Clock {
    fn now_ms(&self) -> u64;
}
