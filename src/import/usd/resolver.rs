//! The folder policy (`import::folder`) for the layers a USD stage opens: sublayers,
//! references, payloads and clip files resolve only inside the scene's folder. A path
//! outside is not resolved (so never opened) and is remembered, for the error. Every
//! layer opened passes the scene-path check of [`super::paths`] first, and raises what
//! the reader may allocate by its size ([`super::cap`]).

use std::cell::RefCell;
use std::collections::HashSet;
use std::io;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use openusd::ar::{Asset, DefaultResolver, ResolvedPath, Resolver};

use crate::import::folder::{resolve_inside, Outside};

/// The paths refused, with why.
pub(super) type Refused = Rc<RefCell<Vec<(String, Outside)>>>;

pub(super) struct FolderResolver {
    inner: DefaultResolver,
    /// The scene's folder, canonical.
    folder: PathBuf,
    refused: Refused,
    /// The layers counted towards what the reader may allocate ([`super::cap`]): the
    /// reader opens some more than once (the root layer twice), each counts once.
    counted: RefCell<HashSet<PathBuf>>,
}

impl FolderResolver {
    pub(super) fn new(folder: PathBuf, refused: Refused) -> Self {
        FolderResolver {
            inner: DefaultResolver::new(),
            folder,
            refused,
            counted: RefCell::default(),
        }
    }

    /// Whether `asset_path` (an identifier: absolute, maybe `pkg.usdz[inner]`) lies
    /// inside the folder.
    fn check(&self, asset_path: &str) -> Result<(), Outside> {
        let outer = asset_path.split('[').next().unwrap_or(asset_path);
        let p = Path::new(outer);
        let rel = if p.is_absolute() {
            p.strip_prefix(&self.folder)
                .map_err(|_| Outside::Absolute)?
        } else {
            p
        };
        resolve_inside(&self.folder, rel).map(|_| ())
    }
}

impl Resolver for FolderResolver {
    fn create_identifier(&self, asset_path: &str, anchor: Option<&ResolvedPath>) -> String {
        self.inner.create_identifier(asset_path, anchor)
    }

    fn resolve(&self, asset_path: &str) -> Option<ResolvedPath> {
        if let Err(why) = self.check(asset_path) {
            self.refused
                .borrow_mut()
                .push((asset_path.to_string(), why));
            return None;
        }
        let resolved = self.inner.resolve(asset_path)?;
        // The resolved file too (a search path or a link may have moved it).
        if let Err(why) = self.check(&resolved.to_string_lossy()) {
            self.refused
                .borrow_mut()
                .push((asset_path.to_string(), why));
            return None;
        }
        Some(resolved)
    }

    fn resolve_for_new_asset(&self, _asset_path: &str) -> Option<ResolvedPath> {
        // The importer writes nothing.
        None
    }

    /// The layer's bytes, once its scene paths pass [`super::paths::check_layer`] (a
    /// malformed path sends the USD reader into recursion without end). Its size
    /// counts towards what the reader may allocate ([`super::cap`]) before it is read.
    fn open_asset(&self, resolved_path: &ResolvedPath) -> io::Result<Box<dyn Asset>> {
        let mut asset = self.inner.open_asset(resolved_path)?;
        if self
            .counted
            .borrow_mut()
            .insert(resolved_path.as_ref().to_path_buf())
        {
            super::cap::layer(asset.size()?);
        }
        let bytes = asset.read_all()?;
        super::paths::check_layer(&bytes)
            .map_err(|why| io::Error::new(io::ErrorKind::InvalidData, why))?;
        Ok(Box::new(Layer(io::Cursor::new(bytes))))
    }

    fn identity(&self) -> String {
        format!("subfield-folder:{}", self.folder.display())
    }
}

/// A layer's bytes, read once: the USD reader's `read_all` takes them without a copy.
struct Layer(io::Cursor<Vec<u8>>);

impl io::Read for Layer {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.0.read(buf)
    }
}

impl io::Seek for Layer {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        self.0.seek(pos)
    }
}

impl Asset for Layer {
    fn size(&self) -> io::Result<u64> {
        Ok(self.0.get_ref().len() as u64)
    }

    /// The bytes not yet read, moved out (all of them for a fresh layer).
    fn read_all(&mut self) -> io::Result<Vec<u8>> {
        let at = usize::try_from(self.0.position()).unwrap_or(usize::MAX);
        let mut bytes = std::mem::take(self.0.get_mut());
        self.0.set_position(0);
        if at > 0 {
            bytes.drain(..at.min(bytes.len()));
        }
        Ok(bytes)
    }
}
