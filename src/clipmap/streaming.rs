//! Asynchronous node loading: worker threads fed through crossbeam channels. The render thread
//! only sends requests and polls results (`try_recv`): it never waits on disk.
//!
//! Requests that became unwanted before a worker reached them are cancelled (the worker checks
//! the shared wanted set first); failures come back as messages, never as panics.

use std::collections::HashSet;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender, unbounded};

use super::{Geometry, NodeData, NodeKey, NodeSource};

/// What a worker did with a request.
pub enum LoadResult {
    /// The node and its shading planes (normals, albedo), computed on the worker.
    Loaded(NodeData, Vec<u8>),
    Failed(String),
    Cancelled,
}

pub struct Streamer {
    requests: Option<Sender<NodeKey>>,
    results: Receiver<(NodeKey, LoadResult)>,
    wanted: Arc<Mutex<HashSet<NodeKey>>>,
    workers: Vec<JoinHandle<()>>,
}

impl Streamer {
    pub fn new(source: Arc<dyn NodeSource>, workers: u32, geometry: Geometry) -> Self {
        let (req_tx, req_rx) = unbounded::<NodeKey>();
        let (res_tx, res_rx) = unbounded();
        let wanted = Arc::new(Mutex::new(HashSet::new()));
        let handles = (0..workers.max(1))
            .map(|i| {
                let (rx, tx, src, wanted, geometry) = (
                    req_rx.clone(),
                    res_tx.clone(),
                    source.clone(),
                    wanted.clone(),
                    geometry.clone(),
                );
                std::thread::Builder::new()
                    .name(format!("clipmap-loader-{i}"))
                    .spawn(move || {
                        for key in rx {
                            let still = wanted
                                .lock()
                                .map(|w: std::sync::MutexGuard<'_, HashSet<NodeKey>>| {
                                    w.contains(&key)
                                })
                                .unwrap_or(true);
                            let result = if !still {
                                LoadResult::Cancelled
                            } else {
                                match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                                    src.load(key)
                                        .and_then(|n| geometry.check(key, &n).map(|()| n))
                                        .map(|n| {
                                            let shading = geometry.shading(key, &n);
                                            (n, shading)
                                        })
                                })) {
                                    Ok(Ok((n, s))) => LoadResult::Loaded(n, s),
                                    Ok(Err(e)) => LoadResult::Failed(e.to_string()),
                                    Err(_) => LoadResult::Failed("loader panicked".into()),
                                }
                            };
                            if tx.send((key, result)).is_err() {
                                break;
                            }
                        }
                    })
            })
            .filter_map(|h| h.ok())
            .collect();
        Streamer {
            requests: Some(req_tx),
            results: res_rx,
            wanted,
            workers: handles,
        }
    }

    /// Replaces the set of nodes some view wants (workers skip requests outside it).
    pub fn set_wanted(&self, wanted: HashSet<NodeKey>) {
        if let Ok(mut w) = self.wanted.lock() {
            *w = wanted;
        }
    }

    /// Queues a load; false if no worker is alive.
    pub fn request(&self, key: NodeKey) -> bool {
        !self.workers.is_empty()
            && self
                .requests
                .as_ref()
                .is_some_and(|tx| tx.send(key).is_ok())
    }

    /// Finished loads, without waiting.
    pub fn poll(&self) -> Vec<(NodeKey, LoadResult)> {
        self.results.try_iter().collect()
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        // Unwanted from now on: queued requests are skipped, then the channel closes.
        self.set_wanted(HashSet::new());
        self.requests.take();
        for h in self.workers.drain(..) {
            let _ = h.join();
        }
    }
}
