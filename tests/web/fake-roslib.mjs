// A stand-in for roslibjs's ROSLIB namespace with the calls Connection makes, for Node tests:
// each Ros records what was sent, and a test fires its 'connection', 'error', 'close' events.
import { EventEmitter } from 'node:events';

export function fakeRoslib() {
  const sockets = [];
  class Ros extends EventEmitter {
    constructor({ url }) {
      super();
      this.url = url;
      this.sent = [];
      this.closed = false;
      sockets.push(this);
    }

    close() {
      this.closed = true;
      this.emit('close');
    }
  }
  class Topic {
    constructor({ ros, name, messageType, throttle_rate: throttle, queue_length: queue }) {
      Object.assign(this, { ros, name, messageType, throttle, queue });
    }

    subscribe(callback) {
      this.ros.sent.push({ op: 'subscribe', topic: this.name, type: this.messageType });
      this.ros.on(`message:${this.name}`, callback);
    }

    unsubscribe() {
      this.ros.sent.push({ op: 'unsubscribe', topic: this.name });
      this.ros.removeAllListeners(`message:${this.name}`);
    }

    publish(message) {
      this.ros.sent.push({ op: 'publish', topic: this.name, msg: message });
    }
  }
  class Service {
    constructor({ ros, name }) {
      Object.assign(this, { ros, name });
    }

    callService(request, ok, fail) {
      this.ros.sent.push({ op: 'call_service', service: this.name, args: request });
      this.ros.emit('call', { name: this.name, request, ok, fail });
    }
  }
  // `new Message(values)` gives back a plain copy (a constructor that returns an object).
  function Plain(values) { return { ...values }; }
  return {
    sockets,
    ROSLIB: { Ros, Topic, Service, Message: Plain, ServiceRequest: Plain },
  };
}
