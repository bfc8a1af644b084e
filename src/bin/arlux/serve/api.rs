//! The HTTP API (docs/serve.md, docs/schema/serve.schema.json): the page,
//! the state, the images, and the edits. Every request carries the token,
//! comes from this host's page (its `Host` and, when sent, `Origin`), is
//! small and within the rate; every reply, refusals included, is JSON but
//! for the page and the images.

use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::Instant;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;
use serde_json::json;
use tokio::sync::oneshot;

use arlux::interactive::{Edit, View};

use super::Shared;
use super::versions::Stamp;
use super::worker::{Job, Reply};

/// The largest request body, bytes: an edit is a few numbers.
const MAX_BODY: usize = 16 * 1024;
/// Requests per second (and burst): a drag sends one per pointer move.
const RATE: u32 = 400;

pub(crate) fn quota() -> governor::Quota {
    let rate = NonZeroU32::new(RATE).expect("non-zero");
    governor::Quota::per_second(rate).allow_burst(rate)
}

const PAGE: &str = include_str!("page/index.html");
const SCRIPT: &str = include_str!("page/app.js");
const STYLE: &str = include_str!("page/style.css");

pub(crate) fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/api/state", get(state))
        .route("/api/image", get(image))
        .route("/api/linear", get(linear))
        .route("/api/place", post(place))
        .route("/api/object", post(object))
        .route("/api/light", post(light))
        .route("/api/add", post(add))
        .route("/api/undo", post(undo))
        .route("/api/redo", post(redo))
        .route("/api/save", post(save))
        .route("/api/render", post(render))
        .fallback(|| async { error(StatusCode::NOT_FOUND, "path", "no such page or API call") })
        .method_not_allowed_fallback(|| async {
            error(
                StatusCode::METHOD_NOT_ALLOWED,
                "method",
                "not allowed on this path",
            )
        })
        .layer(middleware::from_fn_with_state(Arc::clone(&shared), guard))
        .with_state(shared)
}

/// A JSON error naming the field (or the header, or the part of the request) at fault.
fn refused(status: StatusCode, field: &str, message: impl Into<String>) -> Refused {
    Refused(status, field.to_string(), message.into())
}

fn error(status: StatusCode, field: &str, message: impl Into<String>) -> Response {
    let body = json!({ "error": { "field": field, "message": message.into() } });
    (status, axum::Json(body)).into_response()
}

/// A refused request: its status, the field at fault and why.
struct Refused(StatusCode, String, String);

impl IntoResponse for Refused {
    fn into_response(self) -> Response {
        error(self.0, &self.1, self.2)
    }
}

fn reply((status, body): Reply) -> Response {
    let status = StatusCode::from_u16(status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
    (status, axum::Json(body)).into_response()
}

/// The checks every request passes before its handler.
/// The rate is counted over requests that carry the token only: a page or
/// process without it cannot use up the user's quota.
async fn guard(State(shared): State<Arc<Shared>>, request: Request, next: Next) -> Response {
    let headers = request.headers();
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok());
    if !host.is_some_and(|h| shared.hosts.iter().any(|a| a == h)) {
        return error(
            StatusCode::FORBIDDEN,
            "host",
            "the Host header is not this server's address",
        );
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let ok = origin.to_str().ok().and_then(|o| o.strip_prefix("http://"));
        if !ok.is_some_and(|o| shared.hosts.iter().any(|a| a == o)) {
            return error(
                StatusCode::FORBIDDEN,
                "origin",
                "requests come from this server's page only",
            );
        }
    }
    let given = headers
        .get("x-arlux-token")
        .and_then(|t| t.to_str().ok())
        .map(str::to_string)
        .or_else(|| query(request.uri().query(), "token").map(str::to_string));
    if !given.is_some_and(|t| same(t.as_bytes(), shared.token.as_bytes())) {
        return error(
            StatusCode::UNAUTHORIZED,
            "token",
            "a valid token is needed (the address printed at start)",
        );
    }
    if shared.limiter.check().is_err() {
        return error(
            StatusCode::TOO_MANY_REQUESTS,
            "rate",
            format!("more than {RATE} requests a second"),
        );
    }
    // A declared length beyond the limit is refused before its body is
    // awaited (a client that sends one byte of it is not waited for).
    let declared = (request.headers().get(header::CONTENT_LENGTH))
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > MAX_BODY as u64) {
        return error(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body",
            format!("larger than {MAX_BODY} bytes"),
        );
    }
    let mut response = next.run(request).await;
    response
        .headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    response
}

/// Compares in time independent of where the bytes differ.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

async fn page() -> Response {
    let html = PAGE
        .replace("/*STYLE*/", STYLE)
        .replace("/*SCRIPT*/", SCRIPT);
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], html).into_response()
}

async fn state(State(shared): State<Arc<Shared>>) -> Response {
    if let Some(p) = shared
        .latest
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .as_ref()
    {
        let mut s = p.state.clone();
        s["can_render"] = json!(shared.can_render);
        return axum::Json(s).into_response();
    }
    let status = shared
        .status
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    axum::Json(json!({ "ready": false, "stage": status.stage, "failed": status.failed }))
        .into_response()
}

/// The query's value of `key`, if given.
fn query<'a>(request_query: Option<&'a str>, key: &str) -> Option<&'a str> {
    request_query?
        .split('&')
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
}

/// The view and exposure a query asks for.
fn view_of(q: Option<&str>) -> Result<(View, f32), Refused> {
    let view = match query(q, "view") {
        None => View::Final,
        Some(v) => View::parse(v).ok_or_else(|| {
            refused(
                StatusCode::BAD_REQUEST,
                "view",
                "one of final, photo, shadow, ids",
            )
        })?,
    };
    let ev = match query(q, "ev") {
        None => None,
        Some(v) => Some(
            v.parse::<f32>()
                .ok()
                .filter(|e| e.is_finite() && e.abs() <= 32.0)
                .ok_or_else(|| refused(StatusCode::BAD_REQUEST, "ev", "stops within ±32"))?,
        ),
    };
    Ok((view, ev.unwrap_or(f32::NAN)))
}

/// The latest frame with the fixed images, or a 503 while the preprocess runs.
fn latest(
    shared: &Shared,
) -> Result<
    (
        Arc<super::Published>,
        &(arlux::image_io::Image, arlux::surface_ids::SurfaceIds),
    ),
    Refused,
> {
    let published = shared
        .latest
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    match (published, shared.fixed.get()) {
        (Some(p), Some(f)) => Ok((p, f)),
        _ => Err(refused(
            StatusCode::SERVICE_UNAVAILABLE,
            "state",
            "the first image is being made",
        )),
    }
}

fn binary(bytes: Vec<u8>, width: u32, height: u32, version: u64) -> Response {
    let mut headers = HeaderMap::new();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    for (k, v) in [
        ("x-width", width as u64),
        ("x-height", height as u64),
        ("x-version", version),
    ] {
        headers.insert(k, HeaderValue::from(v));
    }
    (headers, Body::from(bytes)).into_response()
}

/// The view tone-mapped: 8-bit sRGB RGBA, row-major.
async fn image(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let (view, ev) = view_of(request.uri().query())?;
    let (p, (photo, ids)) = latest(&shared)?;
    let ev = if ev.is_nan() {
        p.state["exposure"].as_f64().unwrap_or(0.0) as f32
    } else {
        ev
    };
    let rgba = p.frame.rgba(photo, ids, view, ev);
    Ok(binary(rgba, photo.width, photo.height, p.frame.version))
}

/// The view's linear data: little-endian f32 RGB, row-major.
async fn linear(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let (view, _) = view_of(request.uri().query())?;
    let (p, (photo, _)) = latest(&shared)?;
    let image = p.frame.linear(photo, view);
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|px| px.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    Ok(binary(bytes, image.width, image.height, p.frame.version))
}

/// The body read whole (at most [`MAX_BODY`]) and parsed as `T`, or a 4xx
/// naming the field at fault.
async fn body<T: serde::de::DeserializeOwned>(request: Request) -> Result<T, Refused> {
    let reading = axum::body::to_bytes(request.into_body(), MAX_BODY);
    let bytes: Bytes = tokio::time::timeout(super::HEADER_TIMEOUT, reading)
        .await
        .map_err(|_| {
            refused(
                StatusCode::REQUEST_TIMEOUT,
                "body",
                format!("not sent within {} s", super::HEADER_TIMEOUT.as_secs()),
            )
        })?
        .map_err(|_| {
            refused(
                StatusCode::PAYLOAD_TOO_LARGE,
                "body",
                format!("larger than {MAX_BODY} bytes"),
            )
        })?;
    let text = if bytes.is_empty() {
        &b"{}"[..]
    } else {
        &bytes[..]
    };
    let mut parser = serde_json::Deserializer::from_slice(text);
    serde_path_to_error::deserialize(&mut parser).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let field = match (path.as_str(), inner.classify()) {
            (".", _) | ("", _) => unknown_field(&inner.to_string()).unwrap_or("body".into()),
            (p, _) => p.to_string(),
        };
        refused(StatusCode::BAD_REQUEST, &field, inner.to_string())
    })
}

/// The field a top-level serde error names (`missing field `x``).
fn unknown_field(message: &str) -> Option<String> {
    let start = message.find('`')? + 1;
    let end = start + message[start..].find('`')?;
    Some(message[start..end].to_string())
}

fn index(names: &[String], name: &str, field: &str) -> Result<usize, Refused> {
    names.iter().position(|n| n == name).ok_or_else(|| {
        refused(
            StatusCode::UNPROCESSABLE_ENTITY,
            field,
            format!(
                "no {field} named '{name}' (the scene has: {})",
                names.join(", ")
            ),
        )
    })
}

/// Hands a job to the worker and waits for its reply.
async fn ask(shared: &Shared, job: impl FnOnce(oneshot::Sender<Reply>) -> Job) -> Response {
    let (tx, rx) = oneshot::channel();
    if shared.jobs.try_send(job(tx)).is_err() {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "state",
            "the session is busy: too many requests are waiting",
        );
    }
    match rx.await {
        Ok(r) => reply(r),
        Err(_) => error(
            StatusCode::INTERNAL_SERVER_ERROR,
            "state",
            "the session failed on this request; it goes on from its last state",
        ),
    }
}

async fn edit(shared: &Shared, edit: Edit, drag: bool, stamp: Stamp) -> Response {
    let received = Instant::now();
    ask(shared, |reply| Job::Edit {
        edit,
        drag,
        stamp,
        received,
        reply,
    })
    .await
}

/// The state version an edit was made on, and the page that made it
/// (both optional: an edit without them is not checked for staleness).
fn stamp(version: Option<u64>, client: Option<String>) -> Result<Stamp, Refused> {
    if client
        .as_ref()
        .is_some_and(|c| c.is_empty() || c.len() > 64)
    {
        return Err(refused(
            StatusCode::BAD_REQUEST,
            "client",
            "1 to 64 characters",
        ));
    }
    Ok(Stamp { version, client })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Place {
    object: String,
    x: f64,
    y: f64,
    #[serde(default)]
    drag: bool,
    version: Option<u64>,
    client: Option<String>,
}

async fn place(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let p: Place = body(request).await?;
    let object = index(&object_names(&shared), &p.object, "object")?;
    let stamp = stamp(p.version, p.client)?;
    Ok(edit(
        &shared,
        Edit::Place {
            object,
            x: p.x,
            y: p.y,
        },
        p.drag,
        stamp,
    )
    .await)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectChange {
    object: String,
    yaw_deg: Option<f64>,
    scale: Option<f64>,
    enabled: Option<bool>,
    /// [right, forward] metres along the floor.
    nudge: Option<[f64; 2]>,
    version: Option<u64>,
    client: Option<String>,
}

async fn object(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let c: ObjectChange = body(request).await?;
    let object = index(&object_names(&shared), &c.object, "object")?;
    let edit_of = match (c.yaw_deg, c.scale, c.enabled, c.nudge) {
        (Some(yaw_deg), None, None, None) => Edit::Turn { object, yaw_deg },
        (None, Some(scale), None, None) => Edit::Scale { object, scale },
        (None, None, Some(enabled), None) => Edit::Enable { object, enabled },
        (None, None, None, Some([right_m, forward_m])) => Edit::Nudge {
            object,
            right_m,
            forward_m,
        },
        _ => {
            return Err(refused(
                StatusCode::BAD_REQUEST,
                "yaw_deg",
                "give exactly one of yaw_deg, scale, enabled, nudge",
            ));
        }
    };
    Ok(edit(&shared, edit_of, false, stamp(c.version, c.client)?).await)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightChange {
    light: String,
    /// A new scale; or, for a virtual light, a place: the image point
    /// (x, y) and the height off the surface seen there.
    scale: Option<f64>,
    x: Option<f64>,
    y: Option<f64>,
    height_m: Option<f64>,
    version: Option<u64>,
    client: Option<String>,
}

async fn light(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let c: LightChange = body(request).await?;
    let light = index(&shared.lights, &c.light, "light")?;
    let stamp = stamp(c.version, c.client)?;
    let edit_of = match (c.scale, c.x, c.y, c.height_m) {
        (Some(scale), None, None, None) => Edit::Light { light, scale },
        (None, Some(x), Some(y), Some(height_m)) => Edit::PlaceLight {
            light,
            x,
            y,
            height_m,
        },
        _ => {
            return Err(refused(
                StatusCode::BAD_REQUEST,
                "scale",
                "give scale, or x, y and height_m (a virtual light's place)",
            ));
        }
    };
    Ok(edit(&shared, edit_of, false, stamp).await)
}

/// The objects' names now (objects added from `--assets` included).
fn object_names(shared: &Shared) -> Vec<String> {
    (shared.objects.read().unwrap_or_else(|e| e.into_inner())).clone()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Add {
    /// A file name `--assets` listed (never a path).
    asset: String,
    x: f64,
    y: f64,
    version: Option<u64>,
    client: Option<String>,
}

async fn add(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let a: Add = body(request).await?;
    let names: Vec<String> = shared.assets.iter().map(|(n, _)| n.clone()).collect();
    if names.is_empty() {
        return Err(refused(
            StatusCode::UNPROCESSABLE_ENTITY,
            "asset",
            "the server offers no assets (start it with --assets DIR)",
        ));
    }
    let file = shared.assets[index(&names, &a.asset, "asset")?].1.clone();
    let stamp = stamp(a.version, a.client)?;
    let received = std::time::Instant::now();
    Ok(ask(&shared, |reply| Job::Add {
        file,
        at: (a.x, a.y),
        stamp,
        received,
        reply,
    })
    .await)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Save {
    name: Option<String>,
    version: Option<u64>,
    client: Option<String>,
}

async fn save(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let s: Save = body(request).await?;
    let stamp = stamp(s.version, s.client)?;
    Ok(ask(&shared, |reply| Job::Save {
        name: s.name,
        stamp,
        reply,
    })
    .await)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Nothing {}

/// An undo or redo: only its stamp.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Step {
    version: Option<u64>,
    client: Option<String>,
}

async fn undo(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let s: Step = body(request).await?;
    Ok(edit(&shared, Edit::Undo, false, stamp(s.version, s.client)?).await)
}

async fn redo(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    let s: Step = body(request).await?;
    Ok(edit(&shared, Edit::Redo, false, stamp(s.version, s.client)?).await)
}

async fn render(State(shared): State<Arc<Shared>>, request: Request) -> Result<Response, Refused> {
    body::<Nothing>(request).await?;
    Ok(ask(&shared, |reply| Job::Render { reply }).await)
}
