// A classic script, run before the page's modules: if they cannot load (web-interface's
// node_modules not installed, a server that does not serve them) or throw, the page says so
// instead of staying blank.
(function watchForFailures() {
  'use strict';

  function showFatal(text) {
    var banner = document.getElementById('fatal');
    if (!banner || !banner.hidden) return;
    banner.textContent = text;
    banner.hidden = false;
  }

  var modules = document.querySelectorAll('script[type="module"]');
  for (var i = 0; i < modules.length; i += 1) {
    modules[i].addEventListener('error', function onModuleError() {
      showFatal('The page\'s scripts could not be loaded. If you run websim from a source '
        + 'checkout, run "npm ci" in web-interface/ (or "bash scripts/test.sh") and reload.');
    });
  }
  window.addEventListener('error', function onError(event) {
    showFatal('Something went wrong in this page: ' + event.message
      + ' (details in the browser console). Reload to try again.');
  });
  window.addEventListener('unhandledrejection', function onRejection(event) {
    console.error('websim: unhandled rejection:', event.reason);
  });
}());
