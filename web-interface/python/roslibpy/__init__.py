"""roslibpy in the browser: the names ``import roslibpy`` gives, as the real package gives them.

The API lives in ``roslibpy.core`` (as in roslibpy, whose exceptions are there too:
``roslibpy.core.ServiceException``, ``roslibpy.core.RosTimeoutError``); see its docstring for
what differs in the browser.
"""

from roslibpy.core import (
    ActionClient,
    Feedback,
    Goal,
    GoalStatus,
    Header,
    Message,
    Param,
    Result,
    Ros,
    Service,
    ServiceRequest,
    ServiceResponse,
    Time,
    Topic,
    __version__,
    set_default_transport,
    set_rosapi_timeout,
)

__all__ = ["ActionClient", "Feedback", "Goal", "GoalStatus", "Header", "Message", "Param",
           "Result", "Ros", "Service", "ServiceRequest", "ServiceResponse", "Time", "Topic",
           "__version__", "set_default_transport", "set_rosapi_timeout"]
