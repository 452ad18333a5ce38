#!/bin/sh
# Write nginx's password file for /admin from the environment; the nginx image runs this
# before nginx starts. Fails closed: without credentials the file is empty and /admin answers
# 401 to everyone, while the students' pages work as usual.
#
#   ADMIN_HTPASSWD            htpasswd lines, e.g. from `htpasswd -nB admin` or
#                             `printf 'admin:%s\n' "$(openssl passwd -apr1)"`; or
#   ADMIN_USER, ADMIN_PASSWORD  one user, hashed here (apr1)
#   HTPASSWD_FILE             where to write (default /etc/nginx/.htpasswd)
#   HTPASSWD_GROUP            the group nginx's workers run as (default nginx)
set -eu

file=${HTPASSWD_FILE:-/etc/nginx/.htpasswd}
group=${HTPASSWD_GROUP:-nginx}

umask 027
if [ -n "${ADMIN_HTPASSWD:-}" ]; then
    printf '%s\n' "$ADMIN_HTPASSWD" > "$file"
    echo "$0: /admin: users from ADMIN_HTPASSWD"
elif [ -n "${ADMIN_USER:-}" ] && [ -n "${ADMIN_PASSWORD:-}" ]; then
    # The password goes through stdin, never onto a command line.
    hash=$(printf '%s' "$ADMIN_PASSWORD" | openssl passwd -apr1 -stdin)
    printf '%s:%s\n' "$ADMIN_USER" "$hash" > "$file"
    echo "$0: /admin: user $ADMIN_USER"
else
    : > "$file"
    echo "$0: /admin is closed: set ADMIN_USER and ADMIN_PASSWORD (or ADMIN_HTPASSWD)" >&2
fi
chgrp "$group" "$file"
