//! `substep run --monitor` driven by headless Chromium through chromedriver (plain HTTP
//! WebDriver calls): the page shows live data, a controlled stop pressed in the page without
//! the token is refused, with the token it stops the run with the ramp-down, and
//! `summary.json` says who stopped it. Skipped, with a message, where Chromium or chromedriver
//! is not installed (`.ci/run` installs Debian's `chromium` and `chromium-driver`).

use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// One HTTP/1.1 request with `Connection: close`; returns (status, body).
fn http(port: u16, method: &str, path: &str, body: Option<&Value>) -> std::io::Result<(u16, String)> {
    let mut s = TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(30)))?;
    let body = body.map(|b| b.to_string()).unwrap_or_default();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )?;
    // Read the head, then exactly Content-Length bytes (chromedriver may keep the connection open).
    let mut r = std::io::BufReader::new(s);
    let mut head = String::new();
    loop {
        let mut line = String::new();
        if std::io::BufRead::read_line(&mut r, &mut line)? == 0 || line == "\r\n" {
            break;
        }
        head.push_str(&line);
        if head.len() > 65536 {
            break;
        }
    }
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    let length = head
        .lines()
        .find_map(|l| {
            l.split_once(':')
                .filter(|(k, _)| k.eq_ignore_ascii_case("content-length"))
        })
        .and_then(|(_, v)| v.trim().parse::<usize>().ok());
    let mut out = Vec::new();
    match length {
        Some(n) => {
            out.resize(n.min(64 << 20), 0);
            r.read_exact(&mut out)?;
        }
        None => {
            r.take(64 << 20).read_to_end(&mut out)?;
        }
    }
    let body = String::from_utf8_lossy(&out).into_owned();
    Ok((status, body))
}

struct Driver {
    port: u16,
    session: String,
    child: Child,
}

impl Driver {
    fn cmd(&self, method: &str, path: &str, body: Option<Value>) -> Value {
        let (_, b) = http(
            self.port,
            method,
            &format!("/session/{}{path}", self.session),
            body.as_ref(),
        )
        .unwrap();
        serde_json::from_str(&b).unwrap_or(Value::Null)
    }
    fn element(&self, css: &str) -> String {
        let v = self.cmd("POST", "/element", Some(json!({"using": "css selector", "value": css})));
        v["value"]
            .as_object()
            .and_then(|o| o.values().next())
            .and_then(|x| x.as_str())
            .unwrap_or_else(|| panic!("no element {css}: {v}"))
            .to_string()
    }
    fn text(&self, css: &str) -> String {
        let e = self.element(css);
        self.cmd("GET", &format!("/element/{e}/text"), None)["value"]
            .as_str()
            .unwrap_or("")
            .to_string()
    }
    fn click(&self, css: &str) {
        let e = self.element(css);
        self.cmd("POST", &format!("/element/{e}/click"), Some(json!({})));
    }
    fn type_into(&self, css: &str, text: &str) {
        let e = self.element(css);
        self.cmd("POST", &format!("/element/{e}/value"), Some(json!({ "text": text })));
    }
    /// Poll `f` every 100 ms for at most `limit`.
    fn wait_for(&self, limit: Duration, what: &str, mut f: impl FnMut(&Self) -> bool) {
        let t0 = Instant::now();
        while !f(self) {
            assert!(t0.elapsed() < limit, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = http(self.port, "DELETE", &format!("/session/{}", self.session), None);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A headless Chromium session (`None` where chromedriver cannot start one) showing the monitor
/// page at `port`, once the monitor answers (bounded wait).
fn open_page(port: u16, profile: &Path) -> Option<Driver> {
    let driver = start_driver(profile)?;
    let t0 = Instant::now();
    while http(port, "GET", "/state", None).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "monitor did not come up");
        std::thread::sleep(Duration::from_millis(100));
    }
    driver.cmd(
        "POST",
        "/url",
        Some(json!({ "url": format!("http://127.0.0.1:{port}/") })),
    );
    Some(driver)
}

fn start_driver(profile: &Path) -> Option<Driver> {
    let port = free_port();
    let child = Command::new(CHROMEDRIVER)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let t0 = Instant::now();
    while http(port, "GET", "/status", None).is_err() {
        if t0.elapsed() > Duration::from_secs(20) {
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let caps = json!({"capabilities": {"alwaysMatch": {"goog:chromeOptions": {
        "binary": CHROMIUM,
        "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1400,1100", format!("--user-data-dir={}", profile.display())]
    }}}});
    let (_, body) = http(port, "POST", "/session", Some(&caps)).ok()?;
    let v: Value = serde_json::from_str(&body).ok()?;
    let session = v["value"]["sessionId"].as_str()?.to_string();
    Some(Driver { port, session, child })
}

/// The two browser runs of this binary one at a time (each is a paced run plus Chromium).
static BROWSER: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn browser_lock() -> std::sync::MutexGuard<'static, ()> {
    BROWSER.lock().unwrap_or_else(|e| e.into_inner())
}

/// Kills the run whatever happens in the test.
struct Kill<'a>(&'a mut Child);
impl Drop for Kill<'_> {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Wait (bounded) for the run to exit.
fn wait_exit(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(t0.elapsed() < limit, "the run did not end after the stop");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn browser_missing(test: &str) -> bool {
    let missing = !Path::new(CHROMIUM).exists() || !Path::new(CHROMEDRIVER).exists();
    if missing {
        eprintln!(
            "SKIPPED {test}: {CHROMIUM} or {CHROMEDRIVER} is missing (apt-get install chromium chromium-driver; \
             .ci/run does this)"
        );
    }
    missing
}

#[test]
fn monitor_page_shows_live_data_and_stops_the_run_with_the_token() {
    let _g = browser_lock();
    if browser_missing("monitor_page_shows_live_data_and_stops_the_run_with_the_token") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("substep_monitor_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let token = "0123456789abcdef-token";
    let out = dir.join("out");
    // From the repository root, as a user runs it: the page's header shows the config's path
    // as given (docs/img/monitor.png is taken from this run).
    let mut run = Command::new(env!("CARGO_BIN_EXE_substep"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["run", "examples/default.toml"])
        .arg("--out")
        .arg(&out)
        .args([
            "--no-plots",
            "--quiet",
            "--pace",
            "1",
            "--monitor-linger",
            "2",
            "--monitor-token",
            token,
        ])
        .arg("--monitor")
        .arg(format!("127.0.0.1:{port}"))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // The run is 20 s of test time at wall-clock pace; kill it whatever happens below.
    let run = Kill(&mut run);
    let Some(driver) = open_page(port, &dir.join("profile")) else {
        eprintln!("SKIPPED: chromedriver did not start a headless Chromium session");
        return;
    };
    driver.wait_for(Duration::from_secs(20), "live data on the page", |d| {
        d.text("#step") != "–"
    });
    let (step1, time1) = (driver.text("#step"), driver.text("#time"));
    std::thread::sleep(Duration::from_millis(700));
    let (step2, time2) = (driver.text("#step"), driver.text("#time"));
    let (s1, s2): (u64, u64) = (step1.parse().unwrap(), step2.parse().unwrap());
    assert!(s2 > s1, "the page did not update: step {step1} then {step2}");
    assert_ne!(time1, time2);
    // The energy ratio needs a full window of the sweep with enough dissipation (it shows "–"
    // while unknown); the paced run lasts 20 s, so it must appear well within 10 s.
    driver.wait_for(Duration::from_secs(10), "the energy ratio on the page", |d| {
        d.text("#eta") != "–"
    });
    // docs/img/monitor.png is taken here (a run in progress).
    if let Ok(p) = std::env::var("SUBSTEP_MONITOR_SCREENSHOT") {
        let png = driver.cmd("GET", "/screenshot", None)["value"]
            .as_str()
            .unwrap_or("")
            .to_string();
        std::fs::write(p, decode_base64(&png)).unwrap();
    }

    // Without the token the stop is refused and the run goes on.
    driver.click("#stop");
    driver.wait_for(Duration::from_secs(10), "the refusal", |d| {
        d.text("#reply").contains("refused")
    });
    let (_, state) = http(port, "GET", "/state", None).unwrap();
    let state: Value = serde_json::from_str(&state).unwrap();
    assert!(state["stop"].is_null(), "{state}");
    assert!(state["finished"].is_null());

    // With the token it starts the controlled stop.
    driver.type_into("#token", token);
    driver.click("#stop");
    driver.wait_for(Duration::from_secs(30), "the final state on the page", |d| {
        d.text("#status").starts_with("finished")
    });
    assert!(
        driver.text("#final_text").contains("operator"),
        "{}",
        driver.text("#final_text")
    );
    let status = wait_exit(&mut *run.0, Duration::from_secs(30));
    assert_eq!(status.code(), Some(1), "a stopped run exits with 1");
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["completed"], false);
    assert_eq!(summary["stopped_by"], "operator");
    assert!(
        summary["reason"].as_str().unwrap().contains("ramped to 0 over 1 s"),
        "{}",
        summary["reason"]
    );
    assert_eq!(summary["ramp_substeps"], 400, "1 s ramp in sub-steps of 2.5 ms");
    let stopped: u64 = summary["steps_done"].as_u64().unwrap();
    assert!(stopped > s2 && stopped < 2000, "stopped at step {stopped}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A real-time run (`--realtime`, the default example: 20 s against the wall clock, Δt = 10 ms,
/// k_sub = 4) with the page attached: hold is shown as unavailable (disabled, with the reason),
/// acknowledge works, a stop without the token is refused, and with the token the real-time
/// thread ramps to the safe position (substeps.csv), `summary.json` says the operator stopped it.
#[test]
fn realtime_run_stops_from_the_page_with_the_token_and_cannot_hold() {
    let _g = browser_lock();
    if browser_missing("realtime_run_stops_from_the_page_with_the_token_and_cannot_hold") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("substep_monitor_rt_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let token = "fedcba9876543210-token";
    let out = dir.join("out");
    let mut run = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args([
            "run",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/default.toml"),
            "--realtime",
        ])
        .arg("--out")
        .arg(&out)
        .args([
            "--no-plots",
            "--quiet",
            "--monitor-linger",
            "2",
            "--monitor-token",
            token,
        ])
        .arg("--monitor")
        .arg(format!("127.0.0.1:{port}"))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let run = Kill(&mut run);
    let Some(driver) = open_page(port, &dir.join("profile")) else {
        eprintln!("SKIPPED: chromedriver did not start a headless Chromium session");
        return;
    };
    driver.wait_for(Duration::from_secs(15), "live data on the page", |d| {
        d.text("#step") != "–"
    });
    let seen: u64 = driver.text("#step").parse().unwrap();
    assert!(driver.text("#rt").starts_with("late steps"), "{}", driver.text("#rt"));

    // Hold: shown as unavailable, with the reason, before anyone clicks.
    for b in ["#hold", "#resume"] {
        let e = driver.element(b);
        assert_eq!(
            driver.cmd("GET", &format!("/element/{e}/enabled"), None)["value"],
            false,
            "{b}"
        );
        let title = driver.cmd("GET", &format!("/element/{e}/attribute/title"), None)["value"]
            .as_str()
            .unwrap_or("")
            .to_string();
        assert!(title.contains("not available in real-time runs"), "{b}: {title}");
    }
    assert!(
        driver.text("#hold_note").contains("rate-dependent"),
        "{}",
        driver.text("#hold_note")
    );
    // A hold posted anyway (not from the page) is refused with the same reason.
    let (code, body) = http(
        port,
        "POST",
        "/control",
        Some(&json!({ "token": token, "action": "hold" })),
    )
    .unwrap();
    assert_eq!(code, 409, "{body}");
    assert!(body.contains("not available in real-time runs"), "{body}");

    // Without the token the stop is refused and the run goes on.
    driver.click("#stop");
    driver.wait_for(Duration::from_secs(10), "the refusal", |d| {
        d.text("#reply").contains("refused")
    });
    let (_, state) = http(port, "GET", "/state", None).unwrap();
    let state: Value = serde_json::from_str(&state).unwrap();
    assert!(state["stop"].is_null(), "{state}");
    assert!(state["finished"].is_null(), "the run ended before the stop: {state}");

    // Acknowledge works in real-time runs too.
    driver.type_into("#token", token);
    driver.click("#ack");
    driver.wait_for(Duration::from_secs(10), "the acknowledgement", |d| {
        d.text("#acks") == "1"
    });

    // With the token: the controlled stop.
    driver.click("#stop");
    driver.wait_for(Duration::from_secs(30), "the final state on the page", |d| {
        d.text("#status").starts_with("finished")
    });
    let final_text = driver.text("#final_text");
    assert!(
        final_text.contains("operator") && final_text.contains("ramped to 0"),
        "{final_text}"
    );
    let status = wait_exit(&mut *run.0, Duration::from_secs(30));
    assert_eq!(status.code(), Some(1), "a stopped run exits with 1, as offline");

    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["mode"], "realtime");
    assert_eq!(summary["completed"], false);
    assert_eq!(summary["stopped_by"], "operator");
    let reason = summary["reason"].as_str().unwrap();
    assert!(
        reason.starts_with("operator stop from the monitor page (token holder); actuators ramped to 0 over 1 s"),
        "{reason}"
    );
    assert_eq!(summary["ramp_substeps"], 400, "1 s ramp in sub-steps of 2.5 ms");
    let done = summary["steps_done"].as_u64().unwrap();
    assert!(
        done >= seen && done < 2000,
        "stopped at step {done}, page showed {seen}"
    );
    assert_eq!(
        summary["stopped_at_step"].as_u64(),
        Some(done + 1),
        "the ramp replaces the next step"
    );

    // Every step up to the stop is in history.csv.
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert_eq!(
        history.lines().count() as u64,
        1 + done + 1,
        "header, initial state, {done} steps"
    );
    // substeps.csv: the 400 ramp sub-steps of step done + 1, linear from the last command to 0.
    let substeps = std::fs::read_to_string(out.join("substeps.csv")).unwrap();
    let mut lines = substeps.lines();
    assert_eq!(lines.next().unwrap(), "step,substep,t,cmd1,fm1,dm1,ramp");
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 400);
    let c1 = rows[0][3];
    assert!(c1.abs() > 1e-6, "the test was away from 0 when stopped: {c1}");
    for (s, r) in rows.iter().enumerate() {
        assert_eq!(r[0] as u64, done + 1);
        assert_eq!(r[1] as usize, s + 1);
        assert_eq!(r[6] as usize, s + 1, "ramp column");
        // d_s = (1 − s/400) d_last, so d_s / d_1 = (400 − s) / 399.
        let expected = c1 * (400 - (s + 1)) as f64 / 399.0;
        assert!(
            (r[3] - expected).abs() <= 1e-9 * c1.abs(),
            "ramp {}: {} vs {expected}",
            s + 1,
            r[3]
        );
    }
    assert_eq!(rows[399][3], 0.0, "the ramp ends at the safe position");
    let _ = std::fs::remove_dir_all(&dir);
}

fn decode_base64(s: &str) -> Vec<u8> {
    let val = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for v in s.bytes().filter_map(val) {
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

/// `[monitor] token` and `address` in the config (no browser needed): the page is served at
/// the config's address, the token is not printed, /control refuses another token (403) and
/// accepts the config's, whose stop ends the run with `stopped_by: operator`.
#[test]
fn the_config_token_opens_the_controls_and_no_other_does() {
    let dir = std::env::temp_dir().join(format!("substep_monitor_token_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let token = "cfg-token-5e1f09a7c3";
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/default.toml")).unwrap();
    let cfg = dir.join("test.toml");
    std::fs::write(
        &cfg,
        format!("{base}\n[monitor]\ntoken = \"{token}\"\naddress = \"127.0.0.1:{port}\"\n"),
    )
    .unwrap();
    let out = dir.join("out");
    let mut run = Command::new(env!("CARGO_BIN_EXE_substep"))
        .arg("run")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .args([
            "--no-plots",
            "--quiet",
            "--pace",
            "2",
            "--monitor-linger",
            "0",
            "--monitor",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    struct Kill<'a>(&'a mut Child);
    impl Drop for Kill<'_> {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut line = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(run.stdout.take().unwrap()), &mut line).unwrap();
    let run = Kill(&mut run);
    assert!(
        line.contains(&format!("http://127.0.0.1:{port}/")) && line.contains("[monitor] token"),
        "{line}"
    );
    assert!(!line.contains(token), "the config's token is printed: {line}");
    let t0 = Instant::now();
    while http(port, "GET", "/state", None).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "monitor did not come up");
        std::thread::sleep(Duration::from_millis(100));
    }
    for wrong in [
        "",
        "cfg-token-5e1f09a7c4",
        "cfg-token-5e1f09a7c3x",
        "0123456789abcdef0123456789abcdef",
    ] {
        let (code, body) = http(
            port,
            "POST",
            "/control",
            Some(&json!({ "token": wrong, "action": "stop" })),
        )
        .unwrap();
        assert_eq!(code, 403, "token {wrong:?}: {body}");
    }
    let (_, state) = http(port, "GET", "/state", None).unwrap();
    let state: Value = serde_json::from_str(&state).unwrap();
    assert!(state["stop"].is_null() && state["finished"].is_null(), "{state}");
    let (code, body) = http(
        port,
        "POST",
        "/control",
        Some(&json!({ "token": token, "action": "ack" })),
    )
    .unwrap();
    assert_eq!(code, 200, "{body}");
    let (code, body) = http(
        port,
        "POST",
        "/control",
        Some(&json!({ "token": token, "action": "stop" })),
    )
    .unwrap();
    assert_eq!(code, 200, "{body}");
    let child = &mut *run.0;
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the run did not end after the stop"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(status.code(), Some(1), "a stopped run exits with 1");
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["stopped_by"], "operator", "{summary}");
    assert_eq!(summary["completed"], false);
    assert!(summary["steps_done"].as_u64().unwrap() < 2000);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad tokens and addresses are refused before the run: exit 2, one line naming the key.
#[test]
fn bad_monitor_tokens_and_addresses_are_refused_naming_the_key() {
    let dir = std::env::temp_dir().join(format!("substep_monitor_bad_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/default.toml")).unwrap();
    let cases: &[(&str, &[&str], &str)] = &[
        ("token = \"\"", &[], "monitor.token: is empty"),
        (
            "token = \"short-token\"",
            &[],
            "monitor.token: is 11 characters; a control token needs at least 16",
        ),
        (
            "token = \"with a space 0123456\"",
            &[],
            "monitor.token: must be printable ASCII without spaces; it contains ' '",
        ),
        (
            "token = \"non-ascii-token-é12345\"",
            &[],
            "monitor.token: must be printable ASCII without spaces; it contains 'é'",
        ),
        (
            "address = \"here\"",
            &[],
            "monitor.address: 'here' is not an address host:port",
        ),
        (
            "",
            &["--monitor", "127.0.0.1:0", "--monitor-token", "1234567"],
            "--monitor-token: is 7 characters; a control token needs at least 16",
        ),
    ];
    for (i, (table, args, expected)) in cases.iter().enumerate() {
        let cfg = dir.join(format!("bad{i}.toml"));
        std::fs::write(&cfg, format!("{base}\n[monitor]\n{table}\n")).unwrap();
        let out = dir.join(format!("out{i}"));
        let o = Command::new(env!("CARGO_BIN_EXE_substep"))
            .arg("run")
            .arg(&cfg)
            .arg("--out")
            .arg(&out)
            .args(["--no-plots", "--quiet"])
            .args(*args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{table} {args:?}: {err}");
        assert!(err.contains(expected), "{table} {args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(!out.exists(), "a refused config wrote {}", out.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Resident memory of a process \[bytes\] (Linux `/proc`).
fn resident_bytes(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// Issue 25: 16 connections that dribble their request one byte at a time (reconnecting when
/// dropped) and 16 event-stream clients that never read do not keep the operator out: the stop
/// with the token is answered 200 at once, the run stops with `stopped_by = "operator"`, and the
/// run's memory grows by less than 16 MB while they are attached.
#[test]
fn the_stop_gets_through_dribbling_and_non_reading_clients() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let dir = std::env::temp_dir().join(format!("substep_monitor_attack_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let token = "attack-test-token-9c1e77";
    let out = dir.join("out");
    let mut run = Command::new(env!("CARGO_BIN_EXE_substep"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["run", "examples/default.toml"])
        .arg("--out")
        .arg(&out)
        .args([
            "--no-plots",
            "--quiet",
            "--pace",
            "1",
            "--monitor-linger",
            "0",
            "--monitor-token",
            token,
        ])
        .arg("--monitor")
        .arg(format!("127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    struct Kill<'a>(&'a mut Child);
    impl Drop for Kill<'_> {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let pid = run.id();
    let run = Kill(&mut run);
    let t0 = Instant::now();
    while http(port, "GET", "/state", None).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "monitor did not come up");
        std::thread::sleep(Duration::from_millis(100));
    }
    // Let the page's history fill a little, then take the baseline.
    std::thread::sleep(Duration::from_millis(1500));
    let before = resident_bytes(pid).expect("VmRSS of the run");

    let attacking = Arc::new(AtomicBool::new(true));
    let mut attackers = Vec::new();
    for _ in 0..16 {
        let on = attacking.clone();
        attackers.push(std::thread::spawn(move || {
            let request = b"GET /state HTTP/1.1\r\nHost: x\r\nX-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\r\n\r\n";
            while on.load(Ordering::Relaxed) {
                let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else {
                    std::thread::sleep(Duration::from_millis(50));
                    continue;
                };
                // One byte every 0.2 s: under any per-read timeout, never a whole request.
                for b in request.iter().cycle() {
                    if !on.load(Ordering::Relaxed) || s.write_all(&[*b]).is_err() {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(200));
                }
            }
        }));
    }
    // Event-stream clients that send their request and never read a byte.
    let mut silent = Vec::new();
    for _ in 0..16 {
        let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
        write!(
            s,
            "GET /events HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n"
        )
        .unwrap();
        silent.push(s);
    }
    // The attack in full swing: every dribbler has reconnected at least once.
    std::thread::sleep(Duration::from_secs(4));
    let during = resident_bytes(pid).expect("VmRSS of the run");
    let asked = Instant::now();
    let (code, body) = http(
        port,
        "POST",
        "/control",
        Some(&json!({ "token": token, "action": "stop" })),
    )
    .unwrap();
    let answered = asked.elapsed();
    assert_eq!(code, 200, "the stop under attack: {body}");
    assert!(
        answered < Duration::from_secs(1),
        "the stop took {answered:?} to be answered under attack"
    );
    let child = &mut *run.0;
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the run did not end after the stop"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    attacking.store(false, Ordering::Relaxed);
    for a in attackers {
        a.join().unwrap();
    }
    drop(silent);
    assert_eq!(status.code(), Some(1), "a stopped run exits with 1");
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["stopped_by"], "operator", "{summary}");
    assert!(summary["steps_done"].as_u64().unwrap() < 2000, "{summary}");
    let growth = during.saturating_sub(before);
    eprintln!(
        "stop answered in {answered:?}; resident memory {:.1} MB before the attack, {:.1} MB during it",
        before as f64 / 1e6,
        during as f64 / 1e6
    );
    assert!(
        growth < 16 << 20,
        "the run's memory grew by {:.1} MB under the attack",
        growth as f64 / 1e6
    );
    let _ = std::fs::remove_dir_all(&dir);
}
