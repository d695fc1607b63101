//! The studio's live feed: every event (a run started, a node finished, progress, the graph
//! changed, a sweep row) goes to every connected browser as a server-sent event. A browser that
//! is slow or gone is dropped rather than waited for: a run never blocks on a client.

use serde_json::Value;
use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Mutex;
use std::time::Duration;

/// Events a client may fall behind by before it is dropped (it reconnects and reloads the state).
const BACKLOG: usize = 4096;

#[derive(Default)]
pub struct Hub {
    subscribers: Mutex<Vec<SyncSender<String>>>,
    sequence: AtomicU64,
}

impl Hub {
    /// Sends `{ "type": kind, ...fields }` to every client.
    pub fn publish(&self, kind: &str, mut fields: Value) {
        if let Value::Object(m) = &mut fields {
            m.insert("type".into(), Value::String(kind.into()));
        }
        let id = self.sequence.fetch_add(1, Ordering::SeqCst) + 1;
        let text = format!("id: {id}\nevent: {kind}\ndata: {fields}\n\n");
        let mut subs = self.subscribers.lock().unwrap_or_else(|e| e.into_inner());
        subs.retain(|s| match s.try_send(text.clone()) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => false,
        });
    }

    pub fn subscribe(&self) -> Receiver<String> {
        let (tx, rx) = sync_channel(BACKLOG);
        self.subscribers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(tx);
        rx
    }

    /// Connected clients (a client that left is counted until the next event or keep-alive
    /// finds it gone).
    pub fn clients(&self) -> usize {
        self.subscribers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .len()
    }
}

/// Streams events to one client until it disconnects (a write fails) or `stop` says so. A comment
/// line every few seconds finds a client that left while nothing happened.
pub fn stream(rx: Receiver<String>, out: &mut dyn Write, stop: &dyn Fn() -> bool) {
    let _ = out.write_all(b"retry: 1000\n: connected\n\n");
    let _ = out.flush();
    loop {
        if stop() {
            return;
        }
        let chunk = match rx.recv_timeout(Duration::from_secs(2)) {
            Ok(text) => text,
            Err(RecvTimeoutError::Timeout) => ": keep-alive\n\n".to_string(),
            Err(RecvTimeoutError::Disconnected) => return,
        };
        if out
            .write_all(chunk.as_bytes())
            .and_then(|()| out.flush())
            .is_err()
        {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_dropped_client_is_forgotten_at_the_next_event() {
        let hub = Hub::default();
        let a = hub.subscribe();
        let b = hub.subscribe();
        assert_eq!(hub.clients(), 2);
        drop(b);
        hub.publish("x", json!({ "n": 1 }));
        assert_eq!(hub.clients(), 1);
        let got = a.try_recv().expect("a still subscribed");
        assert!(
            got.contains("event: x") && got.contains("\"n\":1") && got.contains("\"type\":\"x\"")
        );
    }

    #[test]
    fn a_client_that_falls_behind_is_dropped_not_waited_for() {
        let hub = Hub::default();
        let _slow = hub.subscribe();
        for i in 0..BACKLOG + 1 {
            hub.publish("x", json!({ "i": i }));
        }
        assert_eq!(hub.clients(), 0);
    }
}
