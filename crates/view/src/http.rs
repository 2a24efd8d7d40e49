//! The little HTTP/1.1 the view's port speaks: a request head read with a bound on its size,
//! and a response written whole. The page asks for a handful of small resources, so a server
//! framework would add more than it gives; parsing is httparse's (already in the build).

use std::io;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// A request head larger than this is refused: a browser's is well under 2 KiB, and the
/// buffer must not grow with what a client sends.
pub(crate) const MAX_HEAD: usize = 8 * 1024;
const MAX_HEADERS: usize = 48;

/// A parsed request head.
#[derive(Debug, Clone)]
pub(crate) struct Request {
    pub method: String,
    /// The request target as sent (path and query).
    pub target: String,
    pub path: String,
    query: Vec<(String, String)>,
    /// Headers in order, names as sent.
    pub headers: Vec<(String, Vec<u8>)>,
    pub keep_alive: bool,
}

impl Request {
    /// The value of header `name` (case-insensitive).
    pub(crate) fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).and_then(|(_, v)| std::str::from_utf8(v).ok())
    }

    /// Whether the client asks to switch this connection to a WebSocket.
    pub(crate) fn is_websocket(&self) -> bool {
        self.header("upgrade").is_some_and(|u| u.trim().eq_ignore_ascii_case("websocket"))
    }

    /// The value of query parameter `name`, when given.
    pub(crate) fn param(&self, name: &str) -> Option<&str> {
        self.query.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// What reading a head gave.
#[derive(Debug)]
pub(crate) enum Head {
    Request(Request),
    /// The peer closed before its request was whole (a browser tab closed, a page reloaded).
    Closed,
    /// Not a request this server takes; the reason, for the 400 answer and the log.
    Malformed(&'static str),
}

/// What a head parser says of the bytes so far.
enum Step<T> {
    /// A whole head of this many bytes.
    Done(usize, T),
    /// Not whole yet: read more.
    More,
    /// Not a head it takes.
    Stop(T),
}

/// How reading a head ended short of a parsed one.
enum Short {
    /// Over [`MAX_HEAD`] bytes and still not whole.
    TooLong,
    /// The stream ended first.
    Ended,
}

/// Reads into `buf` until `parse` has a whole head (removed from `buf`; what follows stays)
/// or refuses it: the one loop for requests and responses.
async fn read_head<R: AsyncRead + Unpin, T>(
    r: &mut R,
    buf: &mut Vec<u8>,
    mut parse: impl FnMut(&[u8]) -> Step<T>,
) -> io::Result<Result<T, Short>> {
    loop {
        if !buf.is_empty() {
            match parse(buf) {
                Step::Done(len, head) => {
                    buf.drain(..len);
                    return Ok(Ok(head));
                }
                Step::Stop(head) => return Ok(Ok(head)),
                Step::More => {}
            }
        }
        if buf.len() >= MAX_HEAD {
            return Ok(Err(Short::TooLong));
        }
        if !read_more(r, buf).await? {
            return Ok(Err(Short::Ended));
        }
    }
}

/// Reads one request head into `buf` (bytes after it stay there: a pipelined request).
pub(crate) async fn read_request<R: AsyncRead + Unpin>(r: &mut R, buf: &mut Vec<u8>) -> io::Result<Head> {
    let head = read_head(r, buf, |bytes| {
        let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(bytes) {
            Ok(httparse::Status::Complete(len)) => {
                Step::Done(len, request_of(&req).map_or(Head::Malformed("not an HTTP/1.x request"), Head::Request))
            }
            Ok(httparse::Status::Partial) => Step::More,
            Err(httparse::Error::TooManyHeaders) => Step::Stop(Head::Malformed("too many headers")),
            Err(_) => Step::Stop(Head::Malformed("not an HTTP request")),
        }
    })
    .await?;
    Ok(match head {
        Ok(head) => head,
        Err(Short::TooLong) => Head::Malformed("request head over 8 KiB"),
        Err(Short::Ended) => Head::Closed,
    })
}

/// A response's status and headers.
type ResponseHead = (u16, Vec<(String, Vec<u8>)>);

/// Reads a response head (the upstream WebSocket server's answer) into `buf`: its status and
/// headers, the bytes after it left in `buf`.
pub(crate) async fn read_response<R: AsyncRead + Unpin>(r: &mut R, buf: &mut Vec<u8>) -> io::Result<ResponseHead> {
    let head = read_head(r, buf, |bytes| {
        let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut resp = httparse::Response::new(&mut headers);
        match resp.parse(bytes) {
            Ok(httparse::Status::Complete(len)) => {
                let headers = resp.headers.iter().map(|h| (h.name.to_string(), h.value.to_vec())).collect();
                Step::Done(len, Ok((resp.code.unwrap_or(0), headers)))
            }
            Ok(httparse::Status::Partial) => Step::More,
            Err(e) => Step::Stop(Err(io::Error::new(io::ErrorKind::InvalidData, e))),
        }
    })
    .await?;
    head.unwrap_or_else(|_| Err(io::Error::new(io::ErrorKind::InvalidData, "no complete response head")))
}

/// Reads what is there into `buf`; false at end of stream.
async fn read_more<R: AsyncRead + Unpin>(r: &mut R, buf: &mut Vec<u8>) -> io::Result<bool> {
    let mut chunk = [0u8; 2048];
    let n = r.read(&mut chunk).await?;
    buf.extend_from_slice(&chunk[..n]);
    Ok(n > 0)
}

fn request_of(req: &httparse::Request) -> Option<Request> {
    let (method, target, version) = (req.method?, req.path?, req.version?);
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let headers: Vec<(String, Vec<u8>)> = req.headers.iter().map(|h| (h.name.to_string(), h.value.to_vec())).collect();
    let connection = headers
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case("connection"))
        .map(|(_, v)| String::from_utf8_lossy(v).to_ascii_lowercase());
    // HTTP/1.1 keeps the connection unless told to close; 1.0 closes unless told to keep it.
    let keep_alive = match connection.as_deref() {
        Some(c) if c.contains("close") => false,
        Some(c) if c.contains("keep-alive") => true,
        _ => version == 1,
    };
    let query = query
        .split('&')
        .filter(|kv| !kv.is_empty())
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
            (k.to_string(), v.to_string())
        })
        .collect();
    Some(Request {
        method: method.to_string(),
        target: target.to_string(),
        path: path.to_string(),
        query,
        headers,
        keep_alive,
    })
}

/// A response to write.
#[derive(Debug, Clone)]
pub(crate) struct Response {
    pub status: u16,
    pub content_type: &'static str,
    pub headers: Vec<(&'static str, String)>,
    pub body: Body,
}

/// A response body: an asset compiled in, or bytes made for this answer (shared: a frame's
/// JPEG goes to every page that asks for it).
#[derive(Debug, Clone)]
pub(crate) enum Body {
    Static(&'static [u8]),
    Owned(std::sync::Arc<Vec<u8>>),
}

impl Body {
    pub(crate) fn as_slice(&self) -> &[u8] {
        match self {
            Body::Static(b) => b,
            Body::Owned(b) => b,
        }
    }
}

impl Response {
    pub(crate) fn new(status: u16, content_type: &'static str, body: Body) -> Response {
        Response { status, content_type, headers: Vec::new(), body }
    }

    /// A short plain-text answer (errors).
    pub(crate) fn text(status: u16, text: &str) -> Response {
        Response::new(status, "text/plain; charset=utf-8", Body::Owned(std::sync::Arc::new(text.into())))
    }

    pub(crate) fn with_header(mut self, name: &'static str, value: String) -> Response {
        self.headers.push((name, value));
        self
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        503 => "Service Unavailable",
        _ => "",
    }
}

/// Writes `resp` whole; `head_only` for HEAD requests.
pub(crate) async fn write_response<W: AsyncWrite + Unpin>(
    w: &mut W,
    resp: &Response,
    keep_alive: bool,
    head_only: bool,
) -> io::Result<()> {
    let body = resp.body.as_slice();
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: {}\r\n",
        resp.status,
        reason(resp.status),
        resp.content_type,
        body.len(),
        if keep_alive { "keep-alive" } else { "close" }
    );
    for (name, value) in &resp.headers {
        head.push_str(&format!("{name}: {value}\r\n"));
    }
    head.push_str("\r\n");
    w.write_all(head.as_bytes()).await?;
    if !head_only {
        w.write_all(body).await?;
    }
    w.flush().await
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn head_of(bytes: &[u8]) -> Head {
        let mut r = bytes;
        read_request(&mut r, &mut Vec::new()).await.unwrap()
    }

    #[tokio::test]
    async fn a_get_with_a_query_is_parsed_and_keeps_the_connection() {
        let Head::Request(r) = head_of(b"GET /frame?camera=front&w=320 HTTP/1.1\r\nHost: x\r\n\r\n").await else {
            panic!("not parsed")
        };
        assert_eq!((r.method.as_str(), r.path.as_str()), ("GET", "/frame"));
        assert_eq!((r.param("camera"), r.param("w"), r.param("stamp")), (Some("front"), Some("320"), None));
        assert!(r.keep_alive && !r.is_websocket());
    }

    #[tokio::test]
    async fn an_upgrade_is_a_websocket_and_close_is_honoured() {
        let Head::Request(r) =
            head_of(b"GET / HTTP/1.1\r\nUpgrade: WebSocket\r\nConnection: Upgrade, close\r\n\r\n").await
        else {
            panic!("not parsed")
        };
        assert!(r.is_websocket() && !r.keep_alive);
    }

    #[tokio::test]
    async fn garbage_and_an_endless_head_are_malformed_a_cut_request_is_a_client_gone() {
        assert!(matches!(head_of(b"\x16\x03\x01 hello tls\r\n\r\n").await, Head::Malformed(_)));
        let endless = [b"GET / HTTP/1.1\r\n".as_slice(), &b"X: y\r\n".repeat(2000)].concat();
        assert!(matches!(head_of(&endless).await, Head::Malformed(_)));
        assert!(matches!(head_of(b"GET / HTTP/1.1\r\nHost").await, Head::Closed));
        assert!(matches!(head_of(b"").await, Head::Closed));
    }

    #[tokio::test]
    async fn a_response_states_its_length_and_a_head_request_gets_no_body() {
        let resp = Response::text(404, "no such page");
        let mut out = Vec::new();
        write_response(&mut out, &resp, false, false).await.unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.starts_with("HTTP/1.1 404 Not Found\r\n"), "{text}");
        assert!(text.contains("Content-Length: 12\r\n") && text.ends_with("\r\n\r\nno such page"), "{text}");
        let mut out = Vec::new();
        write_response(&mut out, &resp, true, true).await.unwrap();
        assert!(String::from_utf8(out).unwrap().ends_with("Connection: keep-alive\r\n\r\n"));
    }
}
