// The login form: the token and the operator's name give a session cookie.
const form = document.getElementById("login");
form.addEventListener("submit", async (e) => {
  e.preventDefault();
  const body = { token: document.getElementById("token").value, name: document.getElementById("name").value };
  const r = await fetch("/login", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  if (r.ok) {
    const next = new URLSearchParams(location.search).get("next") || "/";
    location.href = next.startsWith("/") && !next.startsWith("//") ? next : "/";
  } else {
    document.getElementById("error").textContent = (await r.json()).error || "refused";
  }
});
