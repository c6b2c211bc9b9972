//! Durability of map changes: the real server takes a stream of adds,
//! replacements, removals and compactions over HTTP and is killed with
//! SIGKILL at a random moment, again and again; after every restart the map
//! holds every acknowledged change and nothing else (the one request in
//! flight at the kill may or may not have been applied).

mod common;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;
use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_bowloc");
const TOKEN: &str = "kill-test-token-0123456789";

/// One HTTP/1.1 request on its own connection: (status, body).
fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    body: Option<&[u8]>,
) -> std::io::Result<(u16, Value)> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(5))?;
    s.set_read_timeout(Some(Duration::from_secs(60)))?;
    let body = body.unwrap_or(&[]);
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\
         Authorization: Bearer {TOKEN}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )?;
    s.write_all(body)?;
    let mut answer = Vec::new();
    s.read_to_end(&mut answer)?;
    let text = String::from_utf8_lossy(&answer);
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .ok_or_else(|| std::io::Error::other(format!("no status line in {text:?}")))?;
    let json = text
        .split_once("\r\n\r\n")
        .and_then(|(_, b)| serde_json::from_str(b).ok())
        .unwrap_or(Value::Null);
    Ok((status, json))
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

// the caller owns the returned child and kills and waits for it
#[allow(clippy::zombie_processes)]
fn start(config: &Path) -> (Child, SocketAddr) {
    let port = free_port();
    let addr: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let mut child = Command::new(BIN)
        .args(["--log", "warn", "serve", "--config"])
        .arg(config)
        .args(["--listen", &addr.to_string()])
        .env("BOWLOC_AUTH__WRITE_TOKEN", TOKEN)
        // the process's own variable, not a configuration key: the server
        // must start with it (and glibc's malloc defaults)
        .env("BOWLOC_KEEP_BUFFERS", "0")
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let started = Instant::now();
    loop {
        if let Ok((200, _)) = request(addr, "GET", "/readyz", None) {
            return (child, addr);
        }
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the server did not become ready");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The map's images: id → features.
fn listed(addr: SocketAddr) -> HashMap<String, u64> {
    let (status, page) = request(addr, "GET", "/images?limit=1000", None).unwrap();
    assert_eq!(status, 200, "{page}");
    page["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| {
            (
                i["id"].as_str().unwrap().to_owned(),
                i["features"].as_u64().unwrap(),
            )
        })
        .collect()
}

/// What the client knows: the acknowledged state, and the change in flight.
#[derive(Default)]
struct Model {
    images: HashMap<String, u64>,
    /// (id, features after it: None = removed), sent but not answered.
    pending: Option<(String, Option<u64>)>,
    acknowledged: usize,
}

#[test]
fn every_acknowledged_change_survives_sigkill_and_nothing_else_appears() {
    let d = common::dataset("rtabmap-loop");
    let dir = tempfile::tempdir().unwrap();
    let list = dir.path().join("few.txt");
    let images: Vec<std::path::PathBuf> =
        (1..=4).map(|i| d.join(format!("images/{i}.jpg"))).collect();
    std::fs::write(
        &list,
        images
            .iter()
            .map(|p| p.display().to_string() + "\n")
            .collect::<String>(),
    )
    .unwrap();
    let (vocab, map) = (dir.path().join("v.bowvoc"), dir.path().join("m.bowmap"));
    for args in [
        vec![
            "vocab",
            "build",
            "--images",
            list.to_str().unwrap(),
            "--words",
            "64",
            "--out",
        ],
        vec![
            "map",
            "build",
            "--vocab",
            vocab.to_str().unwrap(),
            "--images",
            list.to_str().unwrap(),
            "--out",
        ],
    ] {
        let out = if args[0] == "vocab" { &vocab } else { &map };
        let s = Command::new(BIN)
            .args(["--log", "warn"])
            .args(&args)
            .arg(out)
            .status()
            .unwrap();
        assert!(s.success());
    }
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        format!(
            "[files]\nvocabulary = {:?}\nmap = {:?}\n[bootstrap]\nenabled = false\n\
             [server]\nworkers = 1\ndrain_ms = 100\n[changes]\ncompact_interval_s = 0\n",
            vocab.display().to_string(),
            map.display().to_string()
        ),
    )
    .unwrap();
    // the bodies: a few real images (their feature counts tell them apart)
    let bodies: Vec<Vec<u8>> = (10..16)
        .map(|i| std::fs::read(d.join(format!("images/{i}.jpg"))).unwrap())
        .collect();

    let model = Arc::new(Mutex::new(Model::default()));
    let (child, addr) = start(&config);
    model.lock().unwrap().images = listed(addr);
    let mut child = Some((child, addr));
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let rounds = 30;
    let mut compactions = 0;
    for round in 0..rounds {
        let (mut server, addr) = child.take().unwrap();
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let client = {
            let (model, stop, bodies) = (model.clone(), stop.clone(), bodies.clone());
            let seed = rng.random::<u64>();
            std::thread::spawn(move || {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let mut compacted = 0;
                while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                    let ids: Vec<String> = model.lock().unwrap().images.keys().cloned().collect();
                    let roll = rng.random_range(0..10);
                    let (method, id, body) = if roll < 2 && !ids.is_empty() {
                        let id = ids[rng.random_range(0..ids.len())].clone();
                        ("DELETE", Some(id), None)
                    } else if roll == 2 {
                        ("POST", None, None)
                    } else {
                        let id = format!("added/{}", rng.random_range(0..8));
                        let body = &bodies[rng.random_range(0..bodies.len())];
                        ("PUT", Some(id), Some(body.clone()))
                    };
                    let path = match &id {
                        Some(id) => format!("/images/{}", id.replace('/', "%2F")),
                        None => "/map/compact".to_owned(),
                    };
                    if let Some(id) = &id {
                        // a PUT's features are known only from its answer
                        let after = (method == "PUT").then_some(u64::MAX);
                        model.lock().unwrap().pending = Some((id.clone(), after));
                    }
                    let Ok((status, answer)) = request(addr, method, &path, body.as_deref()) else {
                        return compacted; // killed
                    };
                    let mut m = model.lock().unwrap();
                    m.pending = None;
                    match (method, status) {
                        ("PUT", 200 | 201) => {
                            let f = answer["features"].as_u64().unwrap();
                            m.images.insert(id.unwrap(), f);
                            m.acknowledged += 1;
                        }
                        ("DELETE", 200) => {
                            m.images.remove(&id.unwrap());
                            m.acknowledged += 1;
                        }
                        ("POST", 200) => compacted += 1,
                        _ => panic!("{method} {path}: {status} {answer}"),
                    }
                }
                compacted
            })
        };
        std::thread::sleep(Duration::from_millis(rng.random_range(100..1500)));
        stop.store(true, std::sync::atomic::Ordering::SeqCst);
        server.kill().unwrap(); // SIGKILL
        server.wait().unwrap();
        compactions += client.join().unwrap();

        let (next, addr) = start(&config);
        let got = listed(addr);
        let mut m = model.lock().unwrap();
        let mut want = m.images.clone();
        if let Some((id, after)) = m.pending.take() {
            // the change in flight: applied or not, whole either way
            let applied = match after {
                None => !got.contains_key(&id),
                Some(_) => got.get(&id).is_some_and(|f| want.get(&id) != Some(f)),
            };
            match (applied, after) {
                (true, None) => {
                    want.remove(&id);
                }
                (true, Some(_)) => {
                    want.insert(id.clone(), got[&id]);
                }
                (false, _) => {}
            }
        }
        assert_eq!(
            got, want,
            "round {round}: the map differs from the acknowledged changes"
        );
        m.images = got;
        child = Some((next, addr));
    }
    let (mut last, _) = child.take().unwrap();
    last.kill().unwrap();
    last.wait().unwrap();
    let m = model.lock().unwrap();
    assert!(
        m.acknowledged >= rounds,
        "only {} acknowledged changes over {rounds} kills",
        m.acknowledged
    );
    println!(
        "{rounds} kills, {} acknowledged changes, {compactions} compactions",
        m.acknowledged
    );
}
