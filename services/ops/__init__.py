"""Operating the system: navlearn up, the router, status queries and rendering, ACL and certificates."""
