// Sign-in page: POST /api/auth/login, then back to the page that sent us here (same origin only).
const form = document.getElementById("login-form");
const error = document.getElementById("login-error");

function nextPage() {
  const next = new URLSearchParams(location.search).get("next") || "/";
  return next.startsWith("/") && !next.startsWith("//") ? next : "/";
}

form.addEventListener("submit", async (ev) => {
  ev.preventDefault();
  error.textContent = "";
  const button = document.getElementById("login-submit");
  button.disabled = true;
  button.textContent = "Signing in…";
  try {
    const res = await fetch("/api/auth/login", {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ username: form.username.value, password: form.password.value }),
    });
    if (res.ok) { location.assign(nextPage()); return; }
    const data = await res.json().catch(() => ({}));
    error.textContent = data.detail || `sign-in failed (${res.status})`;
    form.password.value = "";
    form.password.focus();
  } catch (err) {
    error.textContent = `cannot reach the server: ${err.message}`;
  } finally {
    button.disabled = false;
    button.textContent = "Sign in";
  }
});
