// A class robot's page says whose robot it is and the URL the student's own code connects to
// (config.json names the robot; the token is the one this page keeps for it). The URL is
// shown with the token elided and copied whole.

/** The robot a class page belongs to (config.json's `robot`), or null on a single robot. */
export function robotNameOf(config) {
  return config && typeof config.robot === 'string' && config.robot ? config.robot : null;
}

/** What the student's code connects to: the robot's bridge URL with its token, if any. */
export function codeUrl(wsUrl, token) {
  return token ? `${wsUrl}?token=${encodeURIComponent(token)}` : wsUrl;
}

/** The line over the view, in words a student understands (the token itself not shown). */
export function yourRobotText(name, wsUrl, token) {
  if (!token) {
    return `Your robot: ${name}. This page only watches (it has no token): your code `
      + `connects to ${wsUrl}?token=YOUR_TOKEN, with the token from your instructor.`;
  }
  return `Your robot: ${name} \u2014 your code connects to ${wsUrl}?token=\u2026`;
}

/** Copy `text`: the Clipboard API where the page may use it (localhost, https), else a
 *  selected field and the copy command (a plain-http classroom address). */
export async function copyText(text, doc = document) {
  if (globalThis.navigator?.clipboard && globalThis.isSecureContext) {
    await navigator.clipboard.writeText(text);
    return;
  }
  const field = doc.createElement('textarea');
  field.value = text;
  field.setAttribute('readonly', '');
  field.className = 'offscreen';
  doc.body.append(field);
  field.select();
  const copied = doc.execCommand('copy');
  field.remove();
  if (!copied) throw new Error('the browser refused to copy');
}

/**
 * Shows whose robot this is, over the view, and sets the tab's title; nothing on a single
 * robot's page. `currentToken()` is read each time (an open class hands the token later).
 */
export function showYourRobot({ box, text, copy }, config, wsUrl, currentToken, doc = document) {
  const name = robotNameOf(config);
  if (!name) return null;
  doc.title = `${name} \u2014 websim`;
  const render = () => {
    text.textContent = yourRobotText(name, wsUrl, currentToken());
    copy.hidden = !currentToken();
  };
  copy.addEventListener('click', () => {
    copyText(codeUrl(wsUrl, currentToken()), doc).then(() => {
      copy.textContent = 'Copied';
    }).catch(() => { copy.textContent = 'Copy failed: select the address yourself'; });
  });
  render();
  box.hidden = false;
  return render;
}
