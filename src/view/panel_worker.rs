//! The panel gather on a worker thread for the interactive viewer: the render
//! loop sends a [`PanelRequest`] when the eye or the light changes and picks up
//! the newest texture when one is ready; it never waits. The worker runs
//! [`PanelSource::gather`] pass by pass on its own rayon pool and, between
//! passes, restarts from a rough pass when a newer request has arrived.

use std::sync::mpsc::{channel, Receiver, Sender, TryRecvError};
use std::thread::JoinHandle;

use super::panel::{passes_for, PanelRequest, PanelSource, PanelTexture, INTERACTIVE_SAMPLES};

/// A running panel gather.
pub struct PanelWorker {
    requests: Option<Sender<PanelRequest>>,
    textures: Receiver<PanelTexture>,
    thread: Option<JoinHandle<()>>,
}

impl PanelWorker {
    /// Starts the worker on `threads` threads (0: one per core).
    pub fn start(mut source: PanelSource, threads: usize) -> Result<PanelWorker, String> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| format!("panel gather threads: {e}"))?;
        let (request_tx, mut request_rx) = channel::<PanelRequest>();
        let (texture_tx, texture_rx) = channel();
        let passes = passes_for(INTERACTIVE_SAMPLES);
        let thread = std::thread::Builder::new()
            .name("panel gather".into())
            .spawn(move || {
                let mut next = request_rx.recv().ok();
                while let Some(request) = next.take() {
                    // Moved in as `&mut`: the pool needs the closure `Send`, and a `Receiver` is not `Sync`.
                    let (requests, source, pending, textures) = (&mut request_rx, &mut source, &mut next, &texture_tx);
                    pool.install(move || {
                        source.gather(&request, passes, |texture| {
                            if textures.send(texture).is_err() {
                                return false;
                            }
                            // The newest of any requests that arrived during the pass restarts the gather.
                            loop {
                                match requests.try_recv() {
                                    Ok(newer) => *pending = Some(newer),
                                    Err(TryRecvError::Empty) => return pending.is_none(),
                                    Err(TryRecvError::Disconnected) => return false,
                                }
                            }
                        })
                    });
                    if next.is_none() {
                        // Refined to the cap (or the viewer closed): wait for a new eye or light.
                        next = request_rx.recv().ok();
                    }
                }
            })
            .map_err(|e| format!("cannot start the panel gather thread: {e}"))?;
        Ok(PanelWorker { requests: Some(request_tx), textures: texture_rx, thread: Some(thread) })
    }

    /// Asks for a gather (restarting the current one after its pass).
    pub fn request(&self, request: PanelRequest) {
        if let Some(sender) = &self.requests {
            let _ = sender.send(request);
        }
    }

    /// The newest texture finished since the last call, if any, of `generation` or later.
    pub fn latest(&self, generation: u64) -> Option<PanelTexture> {
        self.textures.try_iter().filter(|t| t.generation >= generation).last()
    }
}

impl Drop for PanelWorker {
    fn drop(&mut self) {
        // Closing the request channel ends the worker after its current pass.
        self.requests = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
