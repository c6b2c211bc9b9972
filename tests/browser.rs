//! The page at `GET /` in a real browser: Debian's headless Chromium driven
//! through chromedriver (WebDriver, with `fantoccini`) against the service
//! on a loopback port. It uploads a real query image, waits for the
//! candidates, checks that the top candidate's thumbnail loaded and that the
//! vote race and the verified top candidate's match lines were drawn,
//! submits a corrupt file and checks the error
//! message, and saves screenshots at desktop and phone widths in
//! `target/test-output/browser/`.

mod common;

use bowloc::dataset::image_list;
use bowloc::pipeline::{build_map, build_vocabulary};
use bowloc::server::config::Config;
use bowloc::vocabulary::kmeans::KmeansConfig;
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::json;
use std::net::{SocketAddr, TcpListener as StdListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
const CHROMIUM: &str = "/usr/bin/chromium";

/// Where the screenshots go.
fn output_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output/browser");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A small vocabulary and map of rtabmap-loop's first 20 map images.
fn map_files(dir: &Path) -> (PathBuf, PathBuf) {
    let images: Vec<_> = image_list(&common::dataset("rtabmap-loop").join("map.txt"))
        .unwrap()
        .into_iter()
        .take(20)
        .collect();
    let kmeans = KmeansConfig {
        k: 300,
        seed: 1,
        ..Default::default()
    };
    let vocab = build_vocabulary(&images, &Default::default(), &kmeans, true).unwrap();
    let map = build_map(&vocab, &images, None, "rtab-20", true).unwrap();
    let (v, m) = (dir.join("v.bowvoc"), dir.join("m.bowmap"));
    vocab.save(&v).unwrap();
    map.save(&m).unwrap();
    (v, m)
}

fn free_port() -> u16 {
    StdListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// chromedriver on a loopback port, stopped when dropped.
struct Driver(Child);

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

async fn wait_for_port(port: u16, what: &str) {
    let until = Instant::now() + Duration::from_secs(30);
    while tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .is_err()
    {
        assert!(Instant::now() < until, "{what} did not start listening");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// GET `path` on the service: the whole HTTP answer as text.
async fn get(address: SocketAddr, path: &str) -> String {
    let request = format!("GET {path} HTTP/1.0\r\nHost: x\r\n\r\n");
    tokio::task::spawn_blocking(move || {
        use std::io::{Read, Write};
        let mut s = std::net::TcpStream::connect(address).unwrap();
        s.write_all(request.as_bytes()).unwrap();
        let mut out = String::new();
        let _ = s.read_to_string(&mut out);
        out
    })
    .await
    .unwrap()
}

async fn wait_until<F, Fut>(what: &str, timeout: Duration, mut check: F)
where
    F: FnMut() -> Fut,
    Fut: Future<Output = bool>,
{
    let until = Instant::now() + timeout;
    while !check().await {
        assert!(Instant::now() < until, "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The element with this id.
async fn by_id(client: &Client, id: &str) -> fantoccini::elements::Element {
    client.find(Locator::Id(id)).await.unwrap()
}

/// The text of the element with this id.
async fn text(client: &Client, id: &str) -> String {
    by_id(client, id).await.text().await.unwrap()
}

/// Click the element with this id.
async fn click(client: &Client, id: &str) {
    by_id(client, id).await.click().await.unwrap()
}

async fn js(client: &Client, script: &str) -> serde_json::Value {
    client.execute(script, vec![]).await.unwrap()
}

async fn screenshot(client: &Client, width: u32, height: u32, name: &str) {
    client.set_window_size(width, height).await.unwrap();
    js(client, "window.scrollTo(0, 0); return true").await;
    // the charts redraw on resize
    tokio::time::sleep(Duration::from_millis(300)).await;
    let png = client.screenshot().await.unwrap();
    assert!(png.starts_with(b"\x89PNG"));
    std::fs::write(output_dir().join(name), png).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_localizes_an_upload_and_shows_errors() {
    for tool in [CHROMEDRIVER, CHROMIUM] {
        assert!(
            Path::new(tool).is_file(),
            "{tool} is missing: scripts/setup.sh installs chromium and chromium-driver"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let (v, m) = map_files(dir.path());
    let mut config = Config::default();
    config.files.vocabulary = v;
    config.files.map = m;
    config.files.images = common::dataset("rtabmap-loop");
    config.bootstrap.enabled = false;
    config.server.workers = 1;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(bowloc::server::serve(config, listener, async move {
        let _ = stopped.await;
        "test end"
    }));
    wait_until("the map to load", Duration::from_secs(60), || async {
        let answer = get(address, "/readyz").await;
        answer
            .lines()
            .next()
            .is_some_and(|status| status.contains(" 200 "))
    })
    .await;

    let port = free_port();
    let _driver = Driver(
        Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts"),
    );
    wait_for_port(port, "chromedriver").await;
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": CHROMIUM,
            "args": ["--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1280,1000",
                     "--hide-scrollbars"],
        }),
    );
    let client = ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{port}"))
        .await
        .expect("a WebDriver session with Chromium");

    client.goto(&format!("http://{address}/")).await.unwrap();
    // the map line comes from GET /map
    wait_until("the map description", Duration::from_secs(10), || async {
        let text = text(&client, "map-info").await;
        text.contains("20 images")
    })
    .await;

    // a real query image: rtabmap-loop's query 5 shows the place of map image 4
    let query = common::dataset("rtabmap-loop")
        .join("images/5.jpg")
        .canonicalize()
        .unwrap();
    let file = by_id(&client, "file").await;
    file.send_keys(query.to_str().unwrap()).await.unwrap();
    by_id(&client, "seed").await.send_keys("3").await.unwrap();
    // geometric verification is ticked by default, as the service does
    assert_eq!(
        js(&client, "return document.getElementById('verify').checked").await,
        json!(true)
    );
    click(&client, "submit").await;
    wait_until("the candidates", Duration::from_secs(30), || async {
        js(
            &client,
            "return document.querySelectorAll('#candidates li.candidate').length",
        )
        .await
        .as_u64()
        .unwrap_or(0)
            > 0
    })
    .await;
    let top_name = js(
        &client,
        "return document.querySelector('#candidates li.candidate figcaption span').textContent",
    )
    .await;
    assert!(
        top_name.as_str().unwrap().contains("images/5.jpg"),
        "top candidate: {top_name}"
    );
    // the top thumbnail loaded: a decoded image of non-zero width
    wait_until("the top thumbnail", Duration::from_secs(15), || async {
        js(
            &client,
            "const i = document.querySelector('#candidates li.candidate img'); \
             return !!i && i.complete && i.naturalWidth > 0",
        )
        .await
            == json!(true)
    })
    .await;
    // the vote race was drawn (after the top candidate's matches, whose
    // images load first): the chart says so and has ink on it
    wait_until("the vote race", Duration::from_secs(15), || async {
        js(
            &client,
            "return document.getElementById('race-chart').dataset.drawn === 'true'",
        )
        .await
            == json!(true)
    })
    .await;
    let drawn = js(
        &client,
        "const c = document.getElementById('race-chart'); \
         const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; \
         let ink = 0; for (let k = 3; k < d.length; k += 4) if (d[k] > 0) ink++; \
         return [c.dataset.drawn, ink, c.width]",
    )
    .await;
    assert_eq!(drawn[0], "true", "{drawn}");
    assert!(
        drawn[1].as_u64().unwrap() > 2000,
        "too little drawn: {drawn}"
    );
    let summary = text(&client, "race-summary").await;
    assert!(summary.contains("Stopped at feature"), "{summary}");
    assert!(summary.contains("full search"), "{summary}");
    // verified: the top candidate's inliers are drawn as lines
    wait_until("the match lines", Duration::from_secs(15), || async {
        js(
            &client,
            "return Number(document.getElementById('match-canvas').dataset.lines || 0)",
        )
        .await
        .as_u64()
        .unwrap_or(0)
            >= 12
    })
    .await;
    // the verified top candidate says at what scale its map image sees the scene
    let caption = js(
        &client,
        "return document.querySelector('#candidates li.candidate figcaption').textContent",
    )
    .await;
    assert!(
        caption
            .as_str()
            .is_some_and(|c| c.contains("verified · scale ")),
        "{caption}"
    );
    let error_hidden = js(&client, "return document.getElementById('error').hidden").await;
    assert_eq!(error_hidden, json!(true));

    screenshot(&client, 1280, 1900, "desktop.png").await;
    screenshot(&client, 390, 3400, "phone.png").await;
    // no horizontal scrolling at phone width
    let overflow = js(
        &client,
        "return document.documentElement.scrollWidth - document.documentElement.clientWidth",
    )
    .await;
    assert!(
        overflow.as_i64().unwrap() <= 0,
        "page wider than a phone: {overflow}"
    );
    client.set_window_size(1280, 1000).await.unwrap();

    // a corrupt file: the API's error is shown as a message
    let corrupt = dir.path().canonicalize().unwrap().join("corrupt.jpg");
    std::fs::write(&corrupt, b"\xFF\xD8\xFF this is not really a JPEG").unwrap();
    let file = by_id(&client, "file").await;
    file.clear().await.unwrap();
    file.send_keys(corrupt.to_str().unwrap()).await.unwrap();
    click(&client, "submit").await;
    wait_until("the error message", Duration::from_secs(15), || async {
        js(&client, "return !document.getElementById('error').hidden").await == json!(true)
    })
    .await;
    let message = text(&client, "error").await;
    assert!(message.contains("undecodable_image"), "{message}");
    assert!(message.contains("422"), "{message}");
    screenshot(&client, 390, 900, "phone-error.png").await;

    // a map image as the query: fetched at the side the server downscales
    // queries to (GET /map), within the thumbnail's largest size
    let map = get(address, "/map").await;
    let map: serde_json::Value =
        serde_json::from_str(map.split("\r\n\r\n").nth(1).unwrap()).unwrap();
    let side = map["query_extract"]["max_side"].as_u64().unwrap();
    let side = if side == 0 {
        u64::from(bowloc::server::thumbnails::MAX_SIZE)
    } else {
        side.min(u64::from(bowloc::server::thumbnails::MAX_SIZE))
    };
    js(
        &client,
        "document.getElementById('map-image').value = '4'; return null",
    )
    .await;
    click(&client, "use-map-image").await;
    wait_until(
        "the map image as the query",
        Duration::from_secs(15),
        || async { text(&client, "status").await.contains("map image 4") },
    )
    .await;
    let fetched = js(
        &client,
        "return performance.getEntriesByType('resource').map((e) => e.name) \
         .filter((n) => n.includes('/images/4/thumbnail'))",
    )
    .await;
    let wanted = format!("/images/4/thumbnail?size={side}");
    assert!(
        fetched
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().ends_with(&wanted)),
        "{fetched}"
    );

    // a time budget no tile fits in: the search ends after its first tile
    // and the summary says why (`fixed 1` alone would read every tile)
    js(
        &client,
        "document.getElementById('rule').value = 'fixed'; \
         document.getElementById('threshold').value = '1'; \
         document.getElementById('budget_ms').value = '0.001'; return null",
    )
    .await;
    click(&client, "submit").await;
    wait_until("the budget's stop", Duration::from_secs(30), || async {
        text(&client, "race-summary")
            .await
            .contains("time budget 0.0 ms")
    })
    .await;
    // and the tiles it skipped show as time saved
    let usage = text(&client, "usage").await;
    assert!(usage.contains("Tiles: 1 of"), "{usage}");
    assert!(usage.contains("ms of extraction saved"), "{usage}");

    client.close().await.unwrap();
    let _ = stop.send(());
    server.await.unwrap().unwrap();
}
