//! How much memory one allocation made while the USD reader works may ask for.
//!
//! A `.usdc` stores each array's length before its data, and the `openusd` crate (0.6)
//! allocates what a length says before it reads the data. A damaged length that fits
//! in memory is allocated (and filled) before the read finds the file too short: a
//! length of 8 GB took 15 s and 8.4 GB of memory before its error, and on a farm node
//! whose scheduler limits a task's memory such a file is killed without a word.
//!
//! No undamaged file needs that. The most a file's data can grow when read is bounded:
//! LZ4 expands by at most 255 times, USD's integer coding by at most 32 (a 64-bit value
//! in a 2-bit code), so no array holds more than [`RATIO`] times the bytes of the layers
//! it was read from. While a stage is read ([`Capped`]), this module keeps that bound
//! for the reading thread: [`RATIO`] times the bytes of every layer opened so far (each
//! counted before its bytes are read, so a large layer raises the bound for itself), or
//! [`FLOOR`], the larger. The command's allocator ([`allocation_cap`]) ends the process
//! with one line naming the file where an allocation asks for more. What the importer
//! itself decodes that the layers do not hold (textures) runs [`Uncapped`].
//!
//! The library itself refuses nothing: only a program whose allocator asks
//! [`allocation_cap`] (the `subfield` command) keeps the bound.

use std::cell::Cell;

/// Decoded bytes a layer's byte may become, at most: LZ4's 255 times USD's integer
/// coding's 32, rounded up.
pub const RATIO: u64 = 8192;

/// The bound is never below this (1 GiB): small files with compressed arrays stay far
/// from it.
pub const FLOOR: u64 = 1 << 30;

thread_local! {
    /// The reading thread's bound in bytes; 0 where no stage is being read (or while
    /// [`Uncapped`]).
    static CAP: Cell<u64> = const { Cell::new(0) };
    /// Bytes of the layers opened by the stage being read.
    static LAYERS: Cell<u64> = const { Cell::new(0) };
}

/// The most one allocation on this thread may ask for, while a USD stage is being read
/// here: `None` elsewhere. It allocates nothing and never panics, so a global
/// allocator may call it.
#[inline]
pub fn allocation_cap() -> Option<u64> {
    CAP.try_with(Cell::get).ok().filter(|&c| c > 0)
}

fn bound(layers: u64) -> u64 {
    layers.saturating_mul(RATIO).max(FLOOR)
}

/// While this lives, this thread reads a stage: the bound holds, [`FLOOR`] until its
/// layers (the file named on the command line first) are counted as they open.
pub(super) struct Capped {
    before: (u64, u64),
}

impl Capped {
    pub(super) fn new() -> Capped {
        let before = (
            CAP.with(|c| c.replace(FLOOR)),
            LAYERS.with(|l| l.replace(0)),
        );
        Capped { before }
    }
}

impl Drop for Capped {
    fn drop(&mut self) {
        CAP.with(|c| c.set(self.before.0));
        LAYERS.with(|l| l.set(self.before.1));
    }
}

/// A layer of `bytes` is about to be read: the bound grows by what it may hold (where a
/// stage is being read on this thread; elsewhere nothing changes).
pub(super) fn layer(bytes: u64) {
    let layers = LAYERS.with(|l| {
        let n = l.get().saturating_add(bytes);
        l.set(n);
        n
    });
    CAP.with(|c| {
        if c.get() > 0 {
            c.set(bound(layers));
        }
    });
}

/// While this lives, the reading thread's allocations are not bounded: for what the
/// importer decodes from files other than layers (a texture's pixels).
pub(super) struct Uncapped {
    before: u64,
}

impl Uncapped {
    pub(super) fn new() -> Uncapped {
        Uncapped {
            before: CAP.with(|c| c.replace(0)),
        }
    }
}

impl Drop for Uncapped {
    fn drop(&mut self) {
        CAP.with(|c| c.set(self.before));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_holds_while_a_stage_is_read_and_grows_with_its_layers() {
        assert_eq!(allocation_cap(), None);
        {
            let _read = Capped::new();
            assert_eq!(allocation_cap(), Some(FLOOR));
            layer(1000);
            assert_eq!(allocation_cap(), Some(FLOOR));
            layer(1 << 20);
            assert_eq!(allocation_cap(), Some(((1 << 20) + 1000) * RATIO));
            {
                let _texture = Uncapped::new();
                assert_eq!(allocation_cap(), None);
            }
            assert_eq!(allocation_cap(), Some(((1 << 20) + 1000) * RATIO));
            layer(u64::MAX);
            assert_eq!(allocation_cap(), Some(u64::MAX));
        }
        assert_eq!(allocation_cap(), None);
        // A layer opened with no stage being read (a library user's own resolver call)
        // sets no bound.
        layer(5);
        assert_eq!(allocation_cap(), None);
    }

    #[test]
    fn stages_read_within_stages_restore_the_outer_bound() {
        let _outer = Capped::new();
        layer(1 << 20);
        {
            let _inner = Capped::new();
            assert_eq!(allocation_cap(), Some(FLOOR));
        }
        assert_eq!(allocation_cap(), Some((1 << 20) * RATIO));
    }

    #[test]
    fn the_bound_is_per_thread() {
        let _read = Capped::new();
        assert_eq!(allocation_cap(), Some(FLOOR));
        assert_eq!(std::thread::spawn(allocation_cap).join().ok(), Some(None));
    }
}
