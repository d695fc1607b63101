//! The studio's HTTP server: hyper's HTTP/1 on a small tokio runtime, with the limits a server
//! on a user's machine needs against a hostile page or process (issue 43). Before any request
//! is answered its head must arrive within [`HEADER_TIMEOUT`] and fit [`MAX_HEADER_BYTES`]; the
//! guard (token, Host) is asked before the body is read; a declared body over
//! [`api::MAX_BODY`] is refused unread, and a body that does not arrive within [`BODY_TIMEOUT`]
//! is given up. An idle connection costs no thread and is closed after the header timeout; at
//! most [`MAX_CONNECTIONS`] are open at once and [`MAX_EVENT_STREAMS`] of them stream events.
//! The API itself ([`api::handle`]) runs on tokio's blocking pool, one request a task.

use super::api::{self, Call, Guard, Reply};
use super::session::Studio;
use http_body_util::combinators::UnsyncBoxBody;
use http_body_util::{BodyExt, Full, Limited};
use hyper::body::{Bytes, Frame, Incoming};
use hyper::header::{CACHE_CONTROL, CONTENT_TYPE};
use hyper::{Request, Response};
use hyper_util::rt::{TokioIo, TokioTimer};
use std::convert::Infallible;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, Semaphore};

/// The most bytes a request's head (request line and headers) may take.
pub const MAX_HEADER_BYTES: usize = 32 << 10;
/// The most header lines a request may have.
const MAX_HEADERS: usize = 64;
/// How long a connection may take to send a request's head, idle keep-alive time included.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a request's body may take to arrive once its head has.
const BODY_TIMEOUT: Duration = Duration::from_secs(30);
/// Connections open at once; one more is closed as soon as it is accepted.
pub const MAX_CONNECTIONS: usize = 512;
/// Event streams open at once (each holds a thread while it streams).
pub const MAX_EVENT_STREAMS: usize = 64;
/// How long a connection lives at most: a client that stops reading a response cannot hold its
/// memory for longer (the page's event stream reconnects by itself).
const CONNECTION_LIFETIME: Duration = Duration::from_secs(600);
/// How long an event stream waits for a client that does not read before it drops the client.
const STALLED_CLIENT: Duration = Duration::from_secs(10);

type Body = UnsyncBoxBody<Bytes, Infallible>;

/// Serves the studio on `listener` until `quit` is set (Ctrl-C).
pub fn serve(
    listener: std::net::TcpListener,
    studio: Arc<Studio>,
    guard: Arc<Guard>,
    quit: Arc<AtomicBool>,
) -> std::io::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("studio-http")
        .enable_all()
        .build()?;
    let result = runtime.block_on(accept_loop(listener, studio, guard, quit));
    // Requests still running in the blocking pool finish on their own; the process is ending.
    runtime.shutdown_timeout(Duration::from_millis(500));
    result
}

async fn accept_loop(
    listener: std::net::TcpListener,
    studio: Arc<Studio>,
    guard: Arc<Guard>,
    quit: Arc<AtomicBool>,
) -> std::io::Result<()> {
    listener.set_nonblocking(true)?;
    let listener = tokio::net::TcpListener::from_std(listener)?;
    let connections = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    let streams = Arc::new(Semaphore::new(MAX_EVENT_STREAMS));
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_header_size(MAX_HEADER_BYTES)
        .max_headers(MAX_HEADERS)
        .max_buf_size(MAX_HEADER_BYTES * 2);
    let mut last_refusal: Option<Instant> = None;
    while !quit.load(Ordering::Relaxed) {
        let stream = match tokio::time::timeout(Duration::from_millis(200), listener.accept()).await
        {
            Err(_) => continue,
            Ok(Ok((stream, _))) => stream,
            Ok(Err(e)) => {
                // Out of file descriptors and the like: the server goes on once some close.
                if last_refusal.is_none_or(|t| t.elapsed() > Duration::from_secs(10)) {
                    eprintln!("warning: the studio cannot accept a connection: {e}");
                    last_refusal = Some(Instant::now());
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let Ok(permit) = connections.clone().try_acquire_owned() else {
            drop(stream);
            continue;
        };
        let (studio, guard, streams) = (studio.clone(), guard.clone(), streams.clone());
        let service = hyper::service::service_fn(move |req| {
            respond(studio.clone(), guard.clone(), streams.clone(), req)
        });
        let connection = http.serve_connection(TokioIo::new(stream), service);
        tokio::spawn(async move {
            let _ = tokio::time::timeout(CONNECTION_LIFETIME, connection).await;
            drop(permit);
        });
    }
    Ok(())
}

async fn respond(
    studio: Arc<Studio>,
    guard: Arc<Guard>,
    streams: Arc<Semaphore>,
    req: Request<Incoming>,
) -> Result<Response<Body>, Infallible> {
    // The head alone decides whether the body is read at all.
    let (path, query, method) = {
        let target = req
            .uri()
            .path_and_query()
            .map(|p| p.as_str())
            .unwrap_or("/");
        let (path, query) = api::split_url(target);
        let header = |name| req.headers().get(name).and_then(|v| v.to_str().ok());
        if let Err((status, message)) =
            guard.admits(header("host"), header("x-mesoflow-token"), &query)
        {
            return Ok(reply(api::error(status, message)));
        }
        let declared = header("content-length").and_then(|v| v.trim().parse::<u64>().ok());
        if declared.is_some_and(|n| n > api::MAX_BODY) {
            return Ok(reply(too_large()));
        }
        (path, query, req.method().as_str().to_string())
    };
    let limited = Limited::new(req.into_body(), api::MAX_BODY as usize);
    let body = match tokio::time::timeout(BODY_TIMEOUT, limited.collect()).await {
        Ok(Ok(collected)) => collected.to_bytes().to_vec(),
        Ok(Err(e)) if e.is::<http_body_util::LengthLimitError>() => return Ok(reply(too_large())),
        Ok(Err(e)) => {
            return Ok(reply(api::error(
                400,
                &format!("cannot read the request: {e}"),
            )))
        }
        Err(_) => {
            return Ok(reply(api::error(
                408,
                &format!(
                    "the request's body did not arrive within {} s",
                    BODY_TIMEOUT.as_secs()
                ),
            )))
        }
    };
    let call = Call {
        method,
        path,
        query,
        body,
    };
    let worker = studio.clone();
    let answer = tokio::task::spawn_blocking(move || api::handle(&worker, &call))
        .await
        .unwrap_or_else(|_| {
            api::error(
                500,
                "the studio failed while answering (a bug: its terminal says where)",
            )
        });
    Ok(match answer {
        Reply::Events => events(&studio, streams),
        data => reply(data),
    })
}

fn too_large() -> Reply {
    api::error(
        413,
        &format!(
            "the request's body is over the {} bytes the studio reads",
            api::MAX_BODY
        ),
    )
}

/// The response for a [`Reply::Data`] (never called with [`Reply::Events`]).
fn reply(r: Reply) -> Response<Body> {
    let Reply::Data {
        status,
        content_type,
        headers,
        body,
    } = r
    else {
        return plain(500, "an event stream where a response was expected");
    };
    let mut b = Response::builder()
        .status(status)
        .header(CONTENT_TYPE, content_type)
        .header(CACHE_CONTROL, "no-store");
    for (k, v) in headers {
        b = b.header(k, v);
    }
    b.body(Full::new(Bytes::from(body)).boxed_unsync())
        .unwrap_or_else(|e| plain(500, &format!("cannot make the response: {e}")))
}

fn plain(status: u16, text: &str) -> Response<Body> {
    let mut r = Response::new(Full::new(Bytes::from(text.to_string())).boxed_unsync());
    *r.status_mut() =
        hyper::StatusCode::from_u16(status).unwrap_or(hyper::StatusCode::INTERNAL_SERVER_ERROR);
    r
}

/// The event stream: a thread that hears the studio's events and hands them to the connection
/// through a small channel, until the client goes (the channel closes), stops reading (for
/// [`STALLED_CLIENT`]) or the server stops.
fn events(studio: &Arc<Studio>, streams: Arc<Semaphore>) -> Response<Body> {
    let Ok(permit) = streams.try_acquire_owned() else {
        return reply(api::error(
            503,
            &format!("{MAX_EVENT_STREAMS} event streams are open already; close a page"),
        ));
    };
    let (tx, rx) = mpsc::channel::<Bytes>(16);
    let heard = studio.hub.subscribe();
    std::thread::spawn(move || {
        let _permit = permit;
        let quit = crate::interrupt::cancel_flag();
        super::events::stream(heard, &mut ChannelWriter(tx), &|| {
            quit.load(Ordering::Relaxed)
        });
    });
    Response::builder()
        .status(200)
        .header(CONTENT_TYPE, "text/event-stream")
        .header(CACHE_CONTROL, "no-store")
        .body(ChannelBody(rx).boxed_unsync())
        .unwrap_or_else(|e| plain(500, &format!("cannot make the response: {e}")))
}

/// The writing end of an event stream: each write one chunk of the response.
struct ChannelWriter(mpsc::Sender<Bytes>);

impl std::io::Write for ChannelWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let gone = |why: &str| std::io::Error::new(std::io::ErrorKind::BrokenPipe, why.to_string());
        let mut chunk = Bytes::copy_from_slice(buf);
        let start = Instant::now();
        loop {
            match self.0.try_send(chunk) {
                Ok(()) => return Ok(buf.len()),
                Err(mpsc::error::TrySendError::Closed(_)) => return Err(gone("the client left")),
                Err(mpsc::error::TrySendError::Full(back)) => {
                    if start.elapsed() > STALLED_CLIENT {
                        return Err(gone("the client stopped reading"));
                    }
                    chunk = back;
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The reading end: the response's body, one frame a chunk, ending when the writer does.
struct ChannelBody(mpsc::Receiver<Bytes>);

impl hyper::body::Body for ChannelBody {
    type Data = Bytes;
    type Error = Infallible;
    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Infallible>>> {
        self.0.poll_recv(cx).map(|c| c.map(|b| Ok(Frame::data(b))))
    }
}
