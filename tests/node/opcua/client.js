// An OPC UA client that is not asyncua, for fcmaster's integration tests.
//
// node client.js PLAN.json  → prints one JSON object on stdout.
// PLAN: {url, policy, mode, user, password, pki, steps: [...]} where each step is one of
//   {op: "endpoints"}                              the server's endpoints (no session)
//   {op: "browse", node}                           the browse names under a node
//   {op: "read", nodes: [...]}                     value, status, source/server timestamps
//   {op: "call", object, method, args: [number]}   status and output arguments
//   {op: "write", node, value}                     the write's status
//   {op: "subscribe", nodes, until: {node, value}, timeout_ms}
//                                                  notifications until node shows value
//   {op: "count", nodes, seconds}                  one group of every node: notifications
//                                                  counted for that long (load benchmarks)
//   {op: "hold", file, timeout_ms}                 keep the session open until file exists
// A step that fails records its error and the plan goes on; a failed connection ends it.
"use strict";
const fs = require("fs");
const {
  OPCUAClient, MessageSecurityMode, SecurityPolicy, AttributeIds, UserTokenType,
  DataType, TimestampsToReturn, ClientSubscription,
  ClientMonitoredItem, ClientMonitoredItemGroup,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

function shown(dataValue) {
  const v = dataValue.value ? dataValue.value.value : null;
  return {
    value: v === undefined ? null : (ArrayBuffer.isView(v) ? Array.from(v) : v),
    status: dataValue.statusCode.name,
    source: dataValue.sourceTimestamp ? dataValue.sourceTimestamp.toISOString() : null,
    server: dataValue.serverTimestamp ? dataValue.serverTimestamp.toISOString() : null,
  };
}

async function step(session, s) {
  if (s.op === "browse") {
    const result = await session.browse(s.node);
    return { status: result.statusCode.name,
             names: result.references.map((r) => r.browseName.name) };
  }
  if (s.op === "read") {
    const values = await session.read(s.nodes.map((nodeId) => ({ nodeId, attributeId: AttributeIds.Value })));
    return { values: Object.fromEntries(s.nodes.map((n, i) => [n, shown(values[i])])) };
  }
  if (s.op === "call") {
    const result = await session.call({
      objectId: s.object, methodId: s.method,
      inputArguments: (s.args || []).map((value) => ({ dataType: DataType.Double, value })),
    });
    return { status: result.statusCode.name,
             outputs: (result.outputArguments || []).map((v) => v.value) };
  }
  if (s.op === "write") {
    const status = await session.write({ nodeId: s.node, attributeId: AttributeIds.Value,
      value: { value: { dataType: DataType.Boolean, value: s.value } } });
    return { status: status.name };
  }
  if (s.op === "subscribe") {
    const subscription = ClientSubscription.create(session, {
      requestedPublishingInterval: 100, requestedLifetimeCount: 100,
      requestedMaxKeepAliveCount: 10, publishingEnabled: true,
    });
    const seen = [];
    let done;
    const finished = new Promise((resolve) => { done = resolve; });
    const started = Date.now();
    const items = [];
    for (const nodeId of s.nodes) {
      const item = ClientMonitoredItem.create(subscription, { nodeId, attributeId: AttributeIds.Value },
        { samplingInterval: 0, discardOldest: true, queueSize: 10 }, TimestampsToReturn.Both);
      item.on("changed", (dataValue) => {
        const change = { node: nodeId, ...shown(dataValue) };
        seen.push(change);
        if (s.until && nodeId === s.until.node && change.value === s.until.value) done();
      });
      items.push(item);
    }
    await new Promise((resolve) => subscription.on("started", resolve));
    const subscribed_ms = Date.now() - started;
    const timer = setTimeout(done, s.timeout_ms || 10000);
    await finished;
    clearTimeout(timer);
    await subscription.terminate();
    return { changes: seen, subscribed_ms };
  }
  if (s.op === "count") {
    const subscription = ClientSubscription.create(session, {
      requestedPublishingInterval: 100, requestedLifetimeCount: 100,
      requestedMaxKeepAliveCount: 10, maxNotificationsPerPublish: 0, publishingEnabled: true,
    });
    await new Promise((resolve) => subscription.on("started", resolve));
    const started = Date.now();
    const group = ClientMonitoredItemGroup.create(subscription,
      s.nodes.map((nodeId) => ({ nodeId, attributeId: AttributeIds.Value })),
      { samplingInterval: 0, discardOldest: true, queueSize: 1 }, TimestampsToReturn.Both);
    await new Promise((resolve) => group.on("initialized", resolve));
    const subscribed_ms = Date.now() - started;
    let count = 0;
    group.on("changed", () => { count += 1; });
    // Said on stderr at once, so a benchmark can start its window when every client is in.
    process.stderr.write(`subscribed ${subscribed_ms}\n`);
    await new Promise((resolve) => setTimeout(resolve, s.seconds * 1000));
    await subscription.terminate();
    return { subscribed_ms, count, per_s: count / s.seconds };
  }
  if (s.op === "hold") {
    const until = Date.now() + (s.timeout_ms || 30000);
    while (!fs.existsSync(s.file)) {
      if (Date.now() > until) throw new Error(`no ${s.file} in time`);
      await new Promise((resolve) => setTimeout(resolve, 100));
    }
    return { held: true };
  }
  throw new Error(`unknown step ${s.op}`);
}

async function main() {
  const plan = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
  const out = { steps: [] };
  const certificateManager = new OPCUACertificateManager({
    rootFolder: plan.pki, automaticallyAcceptUnknownCertificate: true,
  });
  await certificateManager.initialize();
  const client = OPCUAClient.create({
    applicationName: "fcmaster-test-client",
    securityMode: MessageSecurityMode[plan.mode || "SignAndEncrypt"],
    securityPolicy: SecurityPolicy[plan.policy || "Basic256Sha256"],
    endpointMustExist: false,
    connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
    clientCertificateManager: certificateManager,
    requestedSessionTimeout: 60000,
  });
  try {
    await client.connect(plan.url);
    if (plan.steps.length && plan.steps[0].op === "endpoints") {
      const endpoints = await client.getEndpoints();
      out.steps.push({ endpoints: endpoints.map((e) => ({
        policy: e.securityPolicyUri.split("#")[1],
        mode: MessageSecurityMode[e.securityMode],
        tokens: (e.userIdentityTokens || []).map((t) => UserTokenType[t.tokenType]),
      })) });
      await client.disconnect();
      process.stdout.write(JSON.stringify(out) + "\n");
      return;
    }
    const identity = plan.user
      ? { type: UserTokenType.UserName, userName: plan.user, password: plan.password }
      : { type: UserTokenType.Anonymous };
    const session = await client.createSession(identity);
    for (const s of plan.steps) {
      try {
        out.steps.push(await step(session, s));
      } catch (err) {
        out.steps.push({ error: String(err.message || err) });
      }
    }
    await session.close();
  } catch (err) {
    out.error = String(err.message || err);
  }
  try { await client.disconnect(); } catch (err) { /* already gone */ }
  process.stdout.write(JSON.stringify(out) + "\n");
}

main().then(() => process.exit(0), (err) => {
  process.stdout.write(JSON.stringify({ error: String(err) }) + "\n");
  process.exit(1);
});
