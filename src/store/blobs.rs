//! Clips and motion files, kept in an object store under keys such as
//! `clips/<id>` and `jobs/<id>/motion.bvh`. The local filesystem under the data
//! folder is the embedded default; writes are atomic (a file appears whole or not
//! at all), so a crash never leaves half a clip or half a motion file behind.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result};
use futures_util::StreamExt;
use object_store::local::LocalFileSystem;
use object_store::path::Path as Key;
use object_store::{GetOptions, GetRange, GetResult, ObjectStore, ObjectStoreExt, PutPayload};
use tokio::io::AsyncReadExt;

/// Bytes per part when a file is copied in.
const PART: usize = 8 << 20;

#[derive(Clone, Debug)]
pub struct Blobs {
    store: Arc<LocalFileSystem>,
}

impl Blobs {
    /// Blobs under the folder `root` (created if needed).
    pub fn local(root: &Path) -> Result<Blobs> {
        std::fs::create_dir_all(root)
            .with_context(|| format!("cannot create {}", root.display()))?;
        let store = LocalFileSystem::new_with_prefix(root)
            .with_context(|| format!("cannot use {} for files", root.display()))?
            .with_automatic_cleanup(true);
        Ok(Blobs {
            store: Arc::new(store),
        })
    }

    /// Copies a local file in as `key`, streaming; returns its size.
    pub async fn put_file(&self, key: &str, file: &Path) -> Result<u64> {
        let mut f = tokio::fs::File::open(file)
            .await
            .with_context(|| format!("cannot read {}", file.display()))?;
        let mut upload = self.store.put_multipart(&Key::from(key)).await?;
        let mut total = 0u64;
        loop {
            let mut buf = Vec::with_capacity(PART);
            let n = (&mut f).take(PART as u64).read_to_end(&mut buf).await?;
            if n == 0 {
                break;
            }
            total += n as u64;
            if let Err(e) = upload.put_part(PutPayload::from(buf)).await {
                let _ = upload.abort().await;
                return Err(e.into());
            }
        }
        upload.complete().await?;
        Ok(total)
    }

    /// A local path at which the engine can read `key` (the engine reads files).
    pub fn local_path(&self, key: &str) -> Result<PathBuf> {
        Ok(self.store.path_to_filesystem(&Key::from(key))?)
    }

    /// The bytes of `key`, or of a byte range of it.
    pub async fn get(&self, key: &str, range: Option<Range<u64>>) -> Result<GetResult> {
        let opts = GetOptions {
            range: range.map(GetRange::Bounded),
            ..GetOptions::default()
        };
        Ok(self.store.get_opts(&Key::from(key), opts).await?)
    }

    /// Deletes `key` (nothing when it is absent).
    pub async fn delete(&self, key: &str) -> Result<()> {
        match self.store.delete(&Key::from(key)).await {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(e.into()),
        }
    }

    /// Deletes every key under `prefix`.
    pub async fn delete_prefix(&self, prefix: &str) -> Result<()> {
        let prefix = Key::from(prefix);
        let mut list = self.store.list(Some(&prefix));
        let mut keys = Vec::new();
        while let Some(meta) = list.next().await {
            keys.push(meta?.location);
        }
        for k in keys {
            self.delete(k.as_ref()).await?;
        }
        Ok(())
    }
}
