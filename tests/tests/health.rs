//! Health and reflection run beside the simulation service, so load
//! balancers can probe the server and tools like grpcurl can discover it.

use meshless_tests::{ServerProcess, within};
use tokio_stream::StreamExt;
use tonic_health::pb::{
    HealthCheckRequest, health_check_response::ServingStatus, health_client::HealthClient,
};
use tonic_reflection::pb::v1::{
    ServerReflectionRequest, server_reflection_client::ServerReflectionClient,
    server_reflection_request::MessageRequest, server_reflection_response::MessageResponse,
};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_and_reflection_are_served() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let channel = within(
        "connect",
        tonic::transport::Endpoint::from_shared(server.grpc_url.clone())
            .expect("url")
            .connect(),
    )
    .await
    .expect("channel");

    let mut health = HealthClient::new(channel.clone());
    let reply = within(
        "health check",
        health.check(HealthCheckRequest {
            service: "meshless.v1.Simulation".into(),
        }),
    )
    .await
    .expect("health answers")
    .into_inner();
    assert_eq!(reply.status, ServingStatus::Serving as i32);

    let mut reflection = ServerReflectionClient::new(channel);
    let request = ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::ListServices(String::new())),
    };
    let mut replies = within(
        "reflection",
        reflection.server_reflection_info(tokio_stream::iter([request])),
    )
    .await
    .expect("reflection answers")
    .into_inner();
    let reply = within("reflection reply", replies.next())
        .await
        .expect("a reply")
        .expect("ok");
    let Some(MessageResponse::ListServicesResponse(list)) = reply.message_response else {
        panic!("expected a service list, got {reply:?}");
    };
    let names: Vec<_> = list.service.iter().map(|s| s.name.as_str()).collect();
    assert!(names.contains(&"meshless.v1.Simulation"), "{names:?}");
}

/// `meshless health`, what a container's health check runs: SERVING and
/// exit 0 against a server, a failure naming the address without one.
#[tokio::test]
async fn meshless_health_probes_the_health_service() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let meshless = meshless_tests::binary("meshless").expect("built");
    let probe = |url: String| {
        let meshless = meshless.clone();
        async move {
            within(
                "meshless health",
                tokio::process::Command::new(meshless)
                    .args(["health", "--server", &url])
                    .output(),
            )
            .await
            .expect("it runs")
        }
    };
    let up = probe(server.grpc_url.clone()).await;
    assert!(
        up.status.success(),
        "{}",
        String::from_utf8_lossy(&up.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&up.stdout).trim(), "SERVING");
    drop(server);
    // Nothing listens on port 1 of loopback.
    let down = probe("http://127.0.0.1:1".into()).await;
    assert!(!down.status.success());
    assert!(
        String::from_utf8_lossy(&down.stderr).contains("127.0.0.1:1"),
        "{}",
        String::from_utf8_lossy(&down.stderr)
    );
}
