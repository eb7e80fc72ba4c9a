//! The server's configuration layers, on the real binary: a TOML file,
//! then environment variables, then flags, each overriding the one
//! before; `--print-config` shows the result with each value's layer and
//! reads back as a file; a file with a key that is no setting is refused
//! naming the settings; JSON logs are one object per line with the
//! session id on the lines about a session; a config or tokens file that
//! is a FIFO or a device fails the start at once, naming it.

use meshless_tests::{TempDir, binary, failed_start, make_fifo, small_scene, within};
use std::process::Stdio;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Command;

async fn print_config(args: &[&str], env: &[(&str, &str)]) -> (bool, String, String) {
    let mut command = Command::new(binary("meshless-server").expect("built"));
    command.args(args).arg("--print-config");
    for (k, v) in env {
        command.env(k, v);
    }
    let out = within("meshless-server --print-config", command.output())
        .await
        .expect("it runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[tokio::test]
async fn file_then_environment_then_flags() {
    let dir = TempDir::new("config");
    let file = dir.0.join("server.toml");
    std::fs::write(
        &file,
        "grpc-addr = \"127.0.0.1:0\"\nmax-sessions = 3\nmax-particles = 500\n\
         zenoh-listen = [\"tcp/127.0.0.1:0\"]\nmax-snapshot-mb = 9\n",
    )
    .expect("written");
    let path = file.to_str().expect("utf-8");
    let (ok, printed, err) = print_config(
        &["--config", path, "--max-snapshot-mb", "7"],
        &[("MESHLESS_MAX_PARTICLES", "1000")],
    )
    .await;
    assert!(ok, "{err}");
    for line in [
        "max-sessions = 3  # file",
        "max-particles = 1000  # environment",
        "max-snapshot-mb = 7  # flag",
        "grpc-addr = \"127.0.0.1:0\"  # file",
        "zenoh-listen = [\"tcp/127.0.0.1:0\"]  # file",
        "max-connections = 512  # default",
        "# memory-budget-mb =  # unset",
    ] {
        assert!(printed.contains(line), "{line:?} missing from\n{printed}");
    }

    // What it prints reads back as a file, to the same values.
    let again = dir.0.join("printed.toml");
    std::fs::write(&again, &printed).expect("written");
    let (ok, reprinted, err) =
        print_config(&["--config", again.to_str().expect("utf-8")], &[]).await;
    assert!(ok, "{err}");
    let values = |text: &str| -> Vec<String> {
        text.lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split("  #").next().unwrap_or_default().to_owned())
            .collect()
    };
    assert_eq!(values(&reprinted), values(&printed));

    // A key that is no setting is refused, naming the settings.
    std::fs::write(&file, "max-sesions = 3\n").expect("written");
    let (ok, _, err) = print_config(&["--config", path], &[]).await;
    assert!(!ok);
    assert!(err.contains("\"max-sesions\" is not a setting"), "{err}");
    assert!(err.contains("max-sessions"), "{err}");
    std::fs::write(&file, "max-sessions = \"lots\"\n").expect("written");
    let (ok, _, err) = print_config(&["--config", path], &[]).await;
    assert!(!ok);
    assert!(err.contains("lots"), "{err}");
}

#[tokio::test]
async fn a_config_file_configures_the_running_server_and_logs_are_json() {
    let dir = TempDir::new("config-run");
    let file = dir.0.join("server.toml");
    std::fs::write(
        &file,
        "grpc-addr = \"127.0.0.1:0\"\nzenoh-listen = [\"tcp/127.0.0.1:0\"]\nmax-sessions = 2\n\
         log-format = \"json\"\nlog = \"info\"\n",
    )
    .expect("written");
    let mut child = Command::new(binary("meshless-server").expect("built"))
        .args(["--config", file.to_str().expect("utf-8")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("started");
    let mut out = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let ready = within("the ready line", out.next_line())
        .await
        .expect("read")
        .expect("a line");
    let grpc = ready
        .split_whitespace()
        .find_map(|p| p.strip_prefix("grpc="))
        .expect("grpc=")
        .to_owned();
    let client = within(
        "connect",
        meshless_client::Client::connect(&format!("http://{grpc}")),
    )
    .await
    .expect("connected");
    let info = within("info", client.server_info()).await.expect("info");
    assert_eq!(info.max_sessions, 2, "from the file");
    let id = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("created")
        .id;
    let mut logs = BufReader::new(child.stderr.take().expect("stderr")).lines();
    let created = within("the session's log line", async {
        loop {
            let line = logs.next_line().await.expect("read").expect("a line");
            let event: serde_json::Value =
                serde_json::from_str(&line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
            if event["fields"]["message"] == "session created" {
                return event;
            }
        }
    })
    .await;
    assert_eq!(created["fields"]["session"], id.as_str(), "{created}");
    assert_eq!(created["level"], "INFO");
}

/// `--config` and `--tokens-file` naming a FIFO (whose open waits for a
/// writer, for ever) or `/dev/zero` (which never ends) stop the start at
/// once with a message naming the file and what it is, instead of
/// hanging or filling memory.
#[tokio::test]
async fn a_config_or_tokens_file_that_is_no_regular_file_fails_fast() {
    let dir = TempDir::new("config-special");
    let fifo = dir.0.join("fifo");
    make_fifo(&fifo);
    let fifo = fifo.to_str().expect("utf-8");
    for (special, kind) in [(fifo, "a FIFO"), ("/dev/zero", "a character device")] {
        for flag in ["--config", "--tokens-file"] {
            let (ok, stderr) = failed_start(&[flag, special]).await;
            assert!(!ok, "{flag} {special} started");
            assert!(
                stderr.contains(special) && stderr.contains(kind),
                "{flag} {special}: the message names neither the file nor what it is: {stderr}"
            );
        }
    }
}
