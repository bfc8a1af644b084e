//! An `arlux serve` process for the tests, and a plain HTTP client for it.

use std::io::BufRead as _;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// A running `arlux serve` on a free loopback port; killed when dropped.
pub struct Server {
    child: Child,
    pub port: u16,
    pub token: String,
    pub url: String,
    agent: ureq::Agent,
}

/// A reply: status, the `x-*` headers that matter, the body.
pub struct Reply {
    pub status: u16,
    pub version: Option<u64>,
    pub content_type: String,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "status {}: not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
}

impl Server {
    /// Starts `arlux serve SCENE --port 0 --json` with `extra` arguments and
    /// waits for the address it prints.
    pub fn start(scene: &str, extra: &[&str]) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_arlux"))
            .args([
                "serve",
                scene,
                "--port",
                "0",
                "--json",
                "--progress",
                "never",
            ])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
        let mut text = String::new();
        loop {
            let mut line = String::new();
            assert!(
                out.read_line(&mut line).unwrap() > 0,
                "serve exited: {text}"
            );
            text.push_str(&line);
            if line.trim_end() == "}" {
                break;
            }
        }
        let v: Value = serde_json::from_str(&text).unwrap();
        let agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(120)))
            .build()
            .into();
        Server {
            child,
            port: v["port"].as_u64().unwrap() as u16,
            token: v["token"].as_str().unwrap().to_string(),
            url: v["url"].as_str().unwrap().to_string(),
            agent,
        }
    }

    pub fn base(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    fn reply(r: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Reply {
        let mut r = r.unwrap();
        let header = |k: &str| {
            r.headers()
                .get(k)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        let version = header("x-version").and_then(|v| v.parse().ok());
        let content_type = header("content-type").unwrap_or_default();
        let status = r.status().as_u16();
        let body = r
            .body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_vec()
            .unwrap();
        Reply {
            status,
            version,
            content_type,
            body,
        }
    }

    /// GET `path` with the token.
    pub fn get(&self, path: &str) -> Reply {
        let url = format!("{}{path}", self.base());
        Self::reply(
            self.agent
                .get(&url)
                .header("x-arlux-token", &self.token)
                .call(),
        )
    }

    /// POST `body` (raw) to `path`, with the token unless `token` is false.
    pub fn post_raw(&self, path: &str, body: &[u8], token: bool) -> Reply {
        let url = format!("{}{path}", self.base());
        let mut request = self.agent.post(&url).content_type("application/json");
        if token {
            request = request.header("x-arlux-token", &self.token);
        }
        Self::reply(request.send(body))
    }

    pub fn post(&self, path: &str, body: &Value) -> Reply {
        self.post_raw(path, body.to_string().as_bytes(), true)
    }

    /// Waits until the first image is made.
    pub fn wait_ready(&self) -> Value {
        let start = Instant::now();
        loop {
            let s = self.get("/api/state").json();
            if s["ready"] == true {
                return s;
            }
            assert!(s["failed"].is_null(), "the session failed: {s}");
            assert!(start.elapsed() < Duration::from_secs(300), "not ready: {s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// The final image's linear data as the server holds it, and its version.
    pub fn linear(&self) -> (Vec<f32>, u64) {
        let r = self.get("/api/linear?view=final");
        assert_eq!(r.status, 200);
        let data = r
            .body
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        (data, r.version.unwrap())
    }

    /// Whether the process is still running.
    pub fn alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Light `name` in a session state's `lights`.
pub fn light_in(state: &Value, name: &str) -> Value {
    (state["lights"].as_array().expect("a state's lights").iter())
        .find(|l| l["name"] == name)
        .unwrap_or_else(|| panic!("no light '{name}' in {state}"))
        .clone()
}

/// A folder for `--assets` holding the OBJ `mesh` as `crate.obj`; its path.
pub fn crate_folder(mesh: &std::path::Path) -> (tempfile::TempDir, String) {
    let assets = tempfile::tempdir().unwrap();
    std::fs::copy(mesh, assets.path().join("crate.obj")).unwrap();
    let folder = assets.path().display().to_string();
    (assets, folder)
}
