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
