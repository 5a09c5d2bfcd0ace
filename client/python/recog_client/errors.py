"""The exceptions of recog_client: one class per canonical gRPC status code, all under RecogError.

Every call of :class:`recog_client.RecognitionClient` raises these instead of ``grpc.RpcError``:
``NotFound`` for an unknown map or model, ``AlreadyExists``, ``InvalidArgument`` (also a
``ValueError``: the client raises it for bad arguments before sending anything),
``PermissionDenied``, ``Unauthenticated``, ``ResourceExhausted`` (the server stayed busy through
every retry), ``Unavailable`` (no server answered, through every retry), ``DeadlineExceeded``
(also a ``TimeoutError``), ``DataLoss`` (corrupt data on the server, or a download that does not
match its announced size and SHA-256), ``Internal``, ... The status code is ``error.code`` (a
``grpc.StatusCode``) and the server's message ``error.details``.
"""

import grpc


class RecogError(Exception):
    """A failed call: ``code`` is its ``grpc.StatusCode``, ``details`` the server's message."""

    code = grpc.StatusCode.UNKNOWN

    def __init__(self, details: str, code: grpc.StatusCode | None = None):
        """An error with ``details``; ``code`` defaults to the class's own."""
        super().__init__(details)
        self.details = details
        if code is not None:
            self.code = code

    def __str__(self) -> str:
        """``CODE: details``."""
        return f"{self.code.name}: {self.details}"


class Cancelled(RecogError):
    """The call was cancelled (e.g. ``stream.cancel()``)."""
    code = grpc.StatusCode.CANCELLED


class Unknown(RecogError):
    """An error without a better code (e.g. an exception raised by a frames iterator)."""
    code = grpc.StatusCode.UNKNOWN


class InvalidArgument(RecogError, ValueError):
    """A bad request: an undecodable image, bad settings, a bad argument."""
    code = grpc.StatusCode.INVALID_ARGUMENT


class DeadlineExceeded(RecogError, TimeoutError):
    """The call's deadline passed."""
    code = grpc.StatusCode.DEADLINE_EXCEEDED


class NotFound(RecogError):
    """An unknown map, frame or model."""
    code = grpc.StatusCode.NOT_FOUND


class AlreadyExists(RecogError):
    """A map or checkpoint directory of that name exists."""
    code = grpc.StatusCode.ALREADY_EXISTS


class PermissionDenied(RecogError):
    """The token lacks the right the call needs (e.g. write)."""
    code = grpc.StatusCode.PERMISSION_DENIED


class ResourceExhausted(RecogError):
    """The server is busy (after every retry), or a message or model is too large."""
    code = grpc.StatusCode.RESOURCE_EXHAUSTED


class FailedPrecondition(RecogError):
    """The server cannot do it in its state (e.g. a stream whose first message is no config)."""
    code = grpc.StatusCode.FAILED_PRECONDITION


class Aborted(RecogError):
    """The call was aborted."""
    code = grpc.StatusCode.ABORTED


class OutOfRange(RecogError):
    """A value past its valid range."""
    code = grpc.StatusCode.OUT_OF_RANGE


class Unimplemented(RecogError):
    """The server does not implement the call."""
    code = grpc.StatusCode.UNIMPLEMENTED


class Internal(RecogError):
    """A server bug."""
    code = grpc.StatusCode.INTERNAL


class Unavailable(RecogError):
    """No server answered (after every retry), or it is shutting down."""
    code = grpc.StatusCode.UNAVAILABLE


class DataLoss(RecogError):
    """Corrupt data: on the server, or a transfer that does not match its checksum."""
    code = grpc.StatusCode.DATA_LOSS


class Unauthenticated(RecogError):
    """No known bearer token."""
    code = grpc.StatusCode.UNAUTHENTICATED


_BY_CODE = {cls.code: cls for cls in RecogError.__subclasses__()}


def from_rpc_error(error: grpc.RpcError) -> RecogError:
    """The RecogError of a failed gRPC call (its code's class, with the server's details)."""
    code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
    details = (error.details() if hasattr(error, "details") else None) or str(error)
    return _BY_CODE.get(code, RecogError)(details, code)
