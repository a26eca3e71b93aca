//! Control client: typed requests over a running [`Pipeline`], with the
//! responses matched by id. Batches that arrive while a request waits are
//! held and handed out by [`Device::next`] in order.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use firmware_protocol::{
    Config, DeviceError, FrameKind, Identity, PROTOCOL_VERSION, Request, RequestFrame, Response,
    encode_frame, to_payload,
};

use crate::link::{ByteWriter, Link, LinkError};
use crate::pipeline::{BatchRecorder, Delivery, LinkAccounting, Pipeline, start_on};

/// Time a device gets to answer a control request.
pub const RESPONSE_TIMEOUT: Duration = Duration::from_secs(3);

/// Why a control exchange failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The transport failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// No answer in time.
    #[error("{link}: no answer to {request} within {timeout:?}")]
    Timeout {
        /// The link.
        link: String,
        /// The request.
        request: String,
        /// How long we waited.
        timeout: Duration,
    },
    /// The device refused.
    #[error("{link}: {request}: {error}")]
    Device {
        /// The link.
        link: String,
        /// The request.
        request: String,
        /// The device's reason.
        error: DeviceError,
    },
    /// An answer that does not fit the request.
    #[error("{link}: {request} answered with {response}")]
    Unexpected {
        /// The link.
        link: String,
        /// The request.
        request: String,
        /// What came back.
        response: String,
    },
    /// The device speaks another protocol version.
    #[error("{link}: device speaks protocol version {device}, this host speaks {host}")]
    ProtocolMismatch {
        /// The link.
        link: String,
        /// Device's version.
        device: u16,
        /// Ours.
        host: u16,
    },
}

/// An opened device with its pipeline running.
pub struct Device {
    description: String,
    writer: Box<dyn ByteWriter>,
    pipeline: Pipeline,
    held: VecDeque<Delivery>,
    next_id: u16,
}

impl Device {
    /// Starts the pipeline on `link` (see [`Pipeline::start`]).
    pub fn open(link: Link, queue_depth: usize) -> Self {
        let description = link.description.clone();
        let (pipeline, writer) = start_on(link, queue_depth);
        Self {
            description,
            writer,
            pipeline,
            held: VecDeque::new(),
            next_id: 1,
        }
    }

    /// What the link is connected to.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// Sends a request without waiting; returns its id.
    pub fn send(&mut self, request: Request) -> Result<u16, ClientError> {
        let id = self.next_id;
        // 0xFFFF is the device's id for unsolicited messages.
        self.next_id = if id >= 0xFFFE { 1 } else { id + 1 };
        let payload = to_payload(&RequestFrame { id, request }).expect("requests always encode");
        let mut frame = Vec::with_capacity(payload.len() + 12);
        encode_frame(FrameKind::Request, &payload, &mut frame).expect("requests are small");
        self.writer.write_all(&frame)?;
        Ok(id)
    }

    /// Sends a request and waits for its response; a device error is an
    /// error.
    pub fn request(&mut self, request: Request) -> Result<Response, ClientError> {
        let name = request_name(&request);
        let id = self.send(request)?;
        let deadline = Instant::now() + RESPONSE_TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.pipeline.deliveries.recv_timeout(left) {
                Ok(Delivery::Response(r)) if r.id == id => {
                    return match r.response {
                        Response::Error(error) => Err(ClientError::Device {
                            link: self.description.clone(),
                            request: name.into(),
                            error,
                        }),
                        other => Ok(other),
                    };
                }
                Ok(Delivery::Ended(e)) => return Err(e.into()),
                Ok(other) => self.held.push_back(other),
                Err(_) => {
                    return Err(ClientError::Timeout {
                        link: self.description.clone(),
                        request: name.into(),
                        timeout: RESPONSE_TIMEOUT,
                    });
                }
            }
        }
    }

    /// Asks who the device is and checks its protocol version.
    pub fn identify(&mut self) -> Result<Identity, ClientError> {
        match self.request(Request::Identify)? {
            Response::Identity(id) if id.protocol_version == PROTOCOL_VERSION => Ok(id),
            Response::Identity(id) => Err(ClientError::ProtocolMismatch {
                link: self.description.clone(),
                device: id.protocol_version,
                host: PROTOCOL_VERSION,
            }),
            other => Err(self.unexpected("Identify", &other)),
        }
    }

    /// Configures the device; returns the configuration it applied.
    pub fn configure(&mut self, config: Config) -> Result<Config, ClientError> {
        match self.request(Request::Configure(config))? {
            Response::Configured(c) => Ok(c),
            other => Err(self.unexpected("Configure", &other)),
        }
    }

    /// Starts streaming.
    pub fn start(&mut self) -> Result<(), ClientError> {
        match self.request(Request::Start)? {
            Response::Started => Ok(()),
            other => Err(self.unexpected("Start", &other)),
        }
    }

    fn unexpected(&self, request: &str, response: &Response) -> ClientError {
        ClientError::Unexpected {
            link: self.description.clone(),
            request: request.into(),
            response: format!("{response:?}"),
        }
    }

    /// The next batch, response or end of link, waiting up to `timeout`.
    pub fn next(&mut self, timeout: Duration) -> Option<Delivery> {
        if let Some(d) = self.held.pop_front() {
            return Some(d);
        }
        self.pipeline.deliveries.recv_timeout(timeout).ok()
    }

    /// Records every accepted batch from now on (see [`Pipeline::record_to`]).
    pub fn record_to(&self, recorder: Box<dyn BatchRecorder>) {
        self.pipeline.record_to(recorder);
    }

    /// Counters so far.
    pub fn accounting(&self) -> LinkAccounting {
        self.pipeline.accounting()
    }

    /// Stops the pipeline; returns the final counters.
    pub fn close(self) -> LinkAccounting {
        self.pipeline.close()
    }
}

fn request_name(r: &Request) -> &'static str {
    match r {
        Request::Identify => "Identify",
        Request::Configure(_) => "Configure",
        Request::Start => "Start",
        Request::Stop => "Stop",
        Request::Status => "Status",
    }
}
