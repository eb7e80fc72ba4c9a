//! The codes of errors that never reach a handler: tonic's codec answers
//! an oversize request with OUT_OF_RANGE and an undecodable one with
//! INTERNAL, which would tell a client that the server broke. This layer
//! gives both the code of their cause, with a message that says what to
//! change, so that every refusal has one documented code
//! (`docs/protocol.md`).

use tonic::{Code, Status};

/// How tonic's decoder words an oversize request.
const OVERSIZE: &str = "Error, decoded message length too large";
/// How prost words an undecodable message.
const UNDECODABLE: &str = "failed to decode Protobuf message";

/// The response with a codec error's code and message replaced; any other
/// response unchanged.
pub fn recode<B: Default>(
    response: tonic::codegen::http::Response<B>,
) -> tonic::codegen::http::Response<B> {
    match Status::from_header_map(response.headers()).and_then(|status| replacement(&status)) {
        Some(status) => status.into_http(),
        None => response,
    }
}

/// What a codec error should have said; `None` for every other status.
fn replacement(status: &Status) -> Option<Status> {
    let message = status.message();
    match status.code() {
        Code::OutOfRange if message.starts_with(OVERSIZE) => {
            Some(Status::resource_exhausted(format!(
                "the request is too large ({}); send a smaller one (fewer hand-placed \
                 particles) or raise the server's --max-request-mb",
                message
                    .trim_start_matches(OVERSIZE)
                    .trim_start_matches(": ")
            )))
        }
        Code::Internal if message.starts_with(UNDECODABLE) => {
            Some(Status::invalid_argument(format!(
                "the request is not a valid protobuf message of the method's type ({}); check \
                 that client and server share a protocol version",
                crate::error::truncate_message(message)
            )))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codec_errors_get_the_code_of_their_cause() {
        let oversize = Status::out_of_range(format!(
            "{OVERSIZE}: found 2000000 bytes, the limit is: 1048576 bytes"
        ));
        let recoded: tonic::codegen::http::Response<()> = recode(oversize.into_http());
        let status = Status::from_header_map(recoded.headers()).expect("a status");
        assert_eq!(status.code(), Code::ResourceExhausted);
        assert!(
            status.message().contains("found 2000000 bytes"),
            "{}",
            status.message()
        );
        assert!(
            status.message().contains("--max-request-mb"),
            "{}",
            status.message()
        );

        let garbled = Status::internal(format!("{UNDECODABLE}: buffer underflow"));
        let recoded: tonic::codegen::http::Response<()> = recode(garbled.into_http());
        let status = Status::from_header_map(recoded.headers()).expect("a status");
        assert_eq!(status.code(), Code::InvalidArgument);

        // The server's own errors keep their codes.
        for own in [
            Status::internal("internal error: frame encoding failed"),
            Status::not_found("no session with id \"x\""),
        ] {
            let code = own.code();
            let kept: tonic::codegen::http::Response<()> = recode(own.into_http());
            let status = Status::from_header_map(kept.headers()).expect("a status");
            assert_eq!(status.code(), code);
        }
    }
}
