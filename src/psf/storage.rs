//! `Buf<T>`: an array either owned or borrowed from shared bytes (a memory-mapped baked
//! file). The traversal sees plain slices either way.

use std::ops::Deref;
use std::sync::Arc;

use bytemuck::Pod;

/// Bytes that outlive every view into them (a memory map, or a decompressed section).
pub type SharedBytes = Arc<dyn AsRef<[u8]> + Send + Sync>;

pub enum Buf<T: Pod> {
    Owned(Vec<T>),
    /// `len` values of `T` at byte `offset` of `bytes`. Constructed only through
    /// [`Buf::shared`], which checks range and alignment, so `deref` cannot fail.
    Shared {
        bytes: SharedBytes,
        offset: usize,
        len: usize,
    },
}

impl<T: Pod> Buf<T> {
    /// A view of `len` values at `offset`; `None` when out of range or misaligned.
    pub fn shared(bytes: SharedBytes, offset: usize, len: usize) -> Option<Buf<T>> {
        let size = len.checked_mul(std::mem::size_of::<T>())?;
        let end = offset.checked_add(size)?;
        let all: &[u8] = (*bytes).as_ref();
        let slice = all.get(offset..end)?;
        bytemuck::try_cast_slice::<u8, T>(slice).ok()?;
        Some(Buf::Shared { bytes, offset, len })
    }

    pub fn is_owned(&self) -> bool {
        matches!(self, Buf::Owned(_))
    }
}

impl<T: Pod> Deref for Buf<T> {
    type Target = [T];

    #[inline]
    fn deref(&self) -> &[T] {
        match self {
            Buf::Owned(v) => v,
            Buf::Shared { bytes, offset, len } => {
                let all: &[u8] = (**bytes).as_ref();
                // Range and alignment were checked in `Buf::shared`, and the bytes are
                // immutable behind the Arc, so this cast succeeds.
                bytemuck::cast_slice(&all[*offset..*offset + *len * std::mem::size_of::<T>()])
            }
        }
    }
}

impl<T: Pod> From<Vec<T>> for Buf<T> {
    fn from(v: Vec<T>) -> Self {
        Buf::Owned(v)
    }
}

impl<T: Pod + std::fmt::Debug> std::fmt::Debug for Buf<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = if self.is_owned() { "owned" } else { "shared" };
        write!(f, "Buf<{kind}, {} items>", self.len())
    }
}
