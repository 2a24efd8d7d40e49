//! The view's one port: a browser's requests get the page (plain HTTP), a WebSocket upgrade is
//! passed to the Foxglove server, which listens on loopback at a port of its own. One address
//! to give a colleague, whichever viewer they open.
//!
//! Viewers built on `@foxglove/ws-protocol` (Lichtblick among them) offer only the
//! subprotocol `foxglove.websocket.v1`, which the Foxglove SDK's server refuses although its
//! messages are those of `foxglove.sdk.v1`; the front offers the SDK's name upstream and
//! answers the viewer with the name it offered.
//!
//! Each connection is a task of its own with bounded buffers and an idle timeout, and at most
//! [`MAX_CONNECTIONS`] are served at once: what a browser does cannot reach the loop.

use std::sync::Arc;
use std::time::Duration;

use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;

use super::http::{self, Head, Request, Response};
use super::page::Page;

/// Connections served at once; more are closed at once (counted).
pub(crate) const MAX_CONNECTIONS: usize = 64;
/// Of those, WebSockets at once: viewers that stay never take every place from the pages.
pub(crate) const MAX_WEBSOCKETS: usize = 16;
/// A connection with no request for this long is closed.
const IDLE: Duration = Duration::from_secs(30);

/// The subprotocol older Foxglove clients offer, and the one the SDK's server takes for it.
const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// Accepts on `listener` until the task is aborted.
pub(crate) fn serve(listener: TcpListener, foxglove_port: u16, page: Arc<Page>) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
        let sockets = Arc::new(Semaphore::new(MAX_WEBSOCKETS));
        loop {
            let Ok((stream, _)) = listener.accept().await else {
                // Out of descriptors or the like: wait instead of spinning.
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            };
            let Ok(slot) = slots.clone().try_acquire_owned() else {
                page.counters.refused("over the connection limit");
                continue;
            };
            let (page, sockets) = (page.clone(), sockets.clone());
            tokio::spawn(async move {
                let _ = stream.set_nodelay(true);
                connection(stream, foxglove_port, &page, &sockets).await;
                drop(slot);
            });
        }
    })
}

/// One connection: requests answered in turn until it closes, idles or upgrades.
async fn connection(mut stream: TcpStream, foxglove_port: u16, page: &Page, sockets: &Arc<Semaphore>) {
    let mut buf = Vec::with_capacity(1024);
    loop {
        let head = match tokio::time::timeout(IDLE, http::read_request(&mut stream, &mut buf)).await {
            Ok(Ok(head)) => head,
            Ok(Err(_)) | Err(_) => return,
        };
        let req = match head {
            Head::Closed => return,
            Head::Malformed(why) => {
                page.counters.bad_request(why);
                let _ = http::write_response(&mut stream, &Response::text(400, why), false, false).await;
                return;
            }
            Head::Request(req) => req,
        };
        if req.is_websocket() {
            let Ok(_socket) = sockets.clone().try_acquire_owned() else {
                page.counters.refused("over the WebSocket limit");
                let busy = Response::text(503, "too many viewers connected: close one");
                let _ = http::write_response(&mut stream, &busy, false, false).await;
                return;
            };
            page.counters.websocket();
            if let Err(e) = websocket(stream, req, buf, foxglove_port).await {
                tracing::debug!("a viewer's WebSocket ended: {e}");
            }
            return;
        }
        let head_only = req.method == "HEAD";
        let resp = page.answer(&req).await;
        if http::write_response(&mut stream, &resp, req.keep_alive, head_only).await.is_err() || !req.keep_alive {
            return;
        }
    }
}

/// Passes an upgrade to the Foxglove server and then the bytes both ways, until either side
/// closes: the first end closes both (a half-closed pair would hold its place for ever, as a
/// client gone without the closing handshake did). `early` holds what the client sent after
/// its request head.
async fn websocket(mut client: TcpStream, req: Request, early: Vec<u8>, foxglove_port: u16) -> std::io::Result<()> {
    let mut upstream = TcpStream::connect(("127.0.0.1", foxglove_port)).await?;
    upstream.set_nodelay(true)?;
    let legacy = offers_only_legacy(&req);
    upstream.write_all(&request_head(&req, legacy)).await?;
    upstream.write_all(&early).await?;
    let mut buf = Vec::new();
    let (status, headers) = http::read_response(&mut upstream, &mut buf).await?;
    client.write_all(&response_head(status, &headers, legacy)).await?;
    client.write_all(&buf).await?;
    let (mut from_client, mut to_client) = client.split();
    let (mut from_upstream, mut to_upstream) = upstream.split();
    tokio::select! {
        r = tokio::io::copy(&mut from_client, &mut to_upstream) => r?,
        r = tokio::io::copy(&mut from_upstream, &mut to_client) => r?,
    };
    Ok(())
}

/// The subprotocols a request offers.
fn offered(req: &Request) -> Vec<&str> {
    req.header("sec-websocket-protocol").map(|p| p.split(',').map(str::trim).collect()).unwrap_or_default()
}

/// Whether the client offers the older protocol name and none of the SDK's.
fn offers_only_legacy(req: &Request) -> bool {
    let offered = offered(req);
    offered.contains(&LEGACY_SUBPROTOCOL) && !offered.iter().any(|p| p.starts_with("foxglove.sdk."))
}

/// The request as sent upstream: the same, with the SDK's subprotocol for a legacy client.
fn request_head(req: &Request, legacy: bool) -> Vec<u8> {
    let start = format!("{} {} HTTP/1.1\r\n", req.method, req.target);
    head_with(start, &req.headers, legacy.then_some(SDK_SUBPROTOCOL))
}

/// The upstream's answer as the client gets it: the legacy name back for a legacy client.
fn response_head(status: u16, headers: &[(String, Vec<u8>)], legacy: bool) -> Vec<u8> {
    let reason = if status == 101 { "Switching Protocols" } else { "" };
    head_with(format!("HTTP/1.1 {status} {reason}\r\n"), headers, legacy.then_some(LEGACY_SUBPROTOCOL))
}

/// A head: its first line, then `headers`, the subprotocol's value replaced by `protocol`
/// when given.
fn head_with(first_line: String, headers: &[(String, Vec<u8>)], protocol: Option<&str>) -> Vec<u8> {
    let mut head = first_line.into_bytes();
    for (name, value) in headers {
        let value = match protocol {
            Some(p) if name.eq_ignore_ascii_case("sec-websocket-protocol") => p.as_bytes(),
            _ => value.as_slice(),
        };
        head.extend_from_slice(name.as_bytes());
        head.extend_from_slice(b": ");
        head.extend_from_slice(value);
        head.extend_from_slice(b"\r\n");
    }
    head.extend_from_slice(b"\r\n");
    head
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn request(text: &str) -> Request {
        let mut r = text.as_bytes();
        match http::read_request(&mut r, &mut Vec::new()).await.unwrap() {
            Head::Request(req) => req,
            other => panic!("{other:?}"),
        }
    }

    #[tokio::test]
    async fn a_legacy_client_is_offered_upstream_under_the_sdks_name_and_answered_with_its_own() {
        let req = request(
            "GET /?a=1 HTTP/1.1\r\nUpgrade: websocket\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n",
        )
        .await;
        assert!(offers_only_legacy(&req));
        let up = String::from_utf8(request_head(&req, true)).unwrap();
        assert!(up.starts_with("GET /?a=1 HTTP/1.1\r\n") && up.contains("Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n"));
        let back = [("Sec-WebSocket-Protocol".to_string(), b"foxglove.sdk.v1".to_vec())];
        let down = String::from_utf8(response_head(101, &back, true)).unwrap();
        assert!(down.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n"), "{down}");
    }

    #[tokio::test]
    async fn a_client_offering_the_sdks_name_passes_unchanged() {
        let req = request(
            "GET / HTTP/1.1\r\nUpgrade: websocket\r\nSec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n\r\n",
        )
        .await;
        assert!(!offers_only_legacy(&req));
        let up = String::from_utf8(request_head(&req, false)).unwrap();
        assert!(up.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n"), "{up}");
    }
}
